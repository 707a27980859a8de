//! Direct volume rendering against a reference ray caster written here, plainly and in f64:
//! exact transfer function, trilinear interpolation of the raw values, central-difference
//! gradients, no tables, no skipping, no early termination.

use glam::{DMat3, DVec3};
use volmorph_render::shading::{linear_to_srgb8, srgb8_to_linear};
use volmorph_render::transfer::corrected_opacity;
use volmorph_render::{
    Camera, ClipPlane, DEFAULT_FOV_Y, DvrOptions, DvrRenderer, DvrVolume, Framing, Orbit,
    Projection, RenderMode, RgbaImage, Shading, TransferFunction, TransferPreset, UpAxis, psnr,
};
use volmorph_volume::{Geometry, Volume};

/// An oblique, anisotropic CT-like volume in Hounsfield units: air around a "head" with a
/// bony shell (~700 HU), soft tissue inside (~40 HU) and a dense blob (~1400 HU).
fn phantom() -> Volume<i16> {
    let axis = DVec3::new(1.0, 1.0, 1.0).normalize();
    let direction = DMat3::from_axis_angle(axis, 25f64.to_radians());
    let g = Geometry::new([26, 22, 15])
        .with_spacing(DVec3::new(1.0, 1.25, 2.0))
        .with_direction(direction)
        .with_origin(DVec3::new(-11.0, -14.0, -12.0));
    let centre = g.index_to_physical(DVec3::new(12.5, 10.5, 7.0));
    Volume::from_fn(g, |i, j, k| {
        let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)) - centre;
        let r = (p / DVec3::new(10.0, 9.0, 11.0)).length();
        let shell = 700.0 * (-((r - 0.85) / 0.12).powi(2)).exp();
        let tissue = if r < 0.85 { 1040.0 } else { 0.0 };
        let blob = 1400.0 * (-(p - DVec3::new(2.0, -1.5, 3.0)).length_squared() / 8.0).exp();
        (-1000.0 + tissue + shell + blob).round() as i16
    })
    .unwrap()
}

/// Trilinear interpolation of the raw values at continuous index `u` (clamped to the box).
fn trilinear(v: &Volume<i16>, u: DVec3) -> f64 {
    let d = v.dims();
    let mut i0 = [0usize; 3];
    let mut f = [0.0; 3];
    for a in 0..3 {
        let x = u[a].clamp(0.0, (d[a] - 1) as f64);
        i0[a] = (x.floor() as usize).min(d[a] - 2);
        f[a] = x - i0[a] as f64;
    }
    let mut s = 0.0;
    for c in 0..8usize {
        let (di, dj, dk) = (c & 1, (c >> 1) & 1, c >> 2);
        let w = [di, dj, dk]
            .iter()
            .zip(f)
            .map(|(&b, t)| if b == 1 { t } else { 1.0 - t })
            .product::<f64>();
        let x = v.get(i0[0] + di, i0[1] + dj, i0[2] + dk).unwrap();
        s += w * f64::from(x);
    }
    s
}

/// What the reference composites per ray.
#[derive(Clone, Copy)]
enum Mode {
    Composite,
    Mip,
    Iso(f64),
}

/// The reference picture.
fn reference(
    v: &Volume<i16>,
    tf: &TransferFunction,
    shading: Option<Shading>,
    cam: &Camera,
    step: f64,
    mode: Mode,
    clip: Option<ClipPlane>,
) -> RgbaImage {
    let g = *v.geometry();
    let a = g.index_to_physical_matrix();
    let a_inv = a.inverse();
    let hi = DVec3::new(
        (g.dims[0] - 1) as f64,
        (g.dims[1] - 1) as f64,
        (g.dims[2] - 1) as f64,
    );
    let lighting = shading.map(|s| s.for_camera(cam).unwrap());
    RgbaImage::from_fn(cam.width(), cam.height(), |x, y| {
        let ray = cam.ray(x, y);
        let o = g.physical_to_index(ray.origin);
        let d = a_inv * ray.dir;
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for ax in 0..3 {
            if d[ax] == 0.0 {
                if o[ax] < 0.0 || o[ax] > hi[ax] {
                    return [0, 0, 0, 255];
                }
                continue;
            }
            let (ta, tb) = ((0.0 - o[ax]) / d[ax], (hi[ax] - o[ax]) / d[ax]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        if let Some(c) = clip {
            let s0 = c.normal.dot(ray.origin - c.point);
            let sd = c.normal.dot(ray.dir);
            if sd > 0.0 {
                t1 = t1.min(-s0 / sd);
            } else if sd < 0.0 {
                t0 = t0.max(-s0 / sd);
            } else if s0 > 0.0 {
                return [0, 0, 0, 255];
            }
        }
        let grad = |u: DVec3| {
            let gu = DVec3::new(
                trilinear(v, u + DVec3::X) - trilinear(v, u - DVec3::X),
                trilinear(v, u + DVec3::Y) - trilinear(v, u - DVec3::Y),
                trilinear(v, u + DVec3::Z) - trilinear(v, u - DVec3::Z),
            ) * 0.5;
            a_inv.transpose() * gu
        };
        let lit = |c: [f64; 3], u: DVec3| match &lighting {
            Some(l) => l.shade(c, grad(u), -ray.dir),
            None => c,
        };
        let (mut color, mut trans) = ([0.0f64; 3], 1.0f64);
        let mut max = f64::NEG_INFINITY;
        let mut k = (t0 / step).ceil();
        let mut prev: Option<f64> = None;
        while k * step < t1 {
            let t = k * step;
            let u = o + d * t;
            let val = trilinear(v, u);
            match mode {
                Mode::Composite => {
                    let (c, op) = tf.lookup(val);
                    let alpha = corrected_opacity(op, step, tf.unit_distance());
                    if alpha > 0.0 {
                        let c = lit(c, u);
                        for ch in 0..3 {
                            color[ch] += trans * alpha * c[ch];
                        }
                        trans *= 1.0 - alpha;
                    }
                }
                Mode::Mip => max = max.max(val),
                Mode::Iso(level) => {
                    if val >= level {
                        let p = match prev {
                            Some(p) if p < level => {
                                u - d * (step * (1.0 - (level - p) / (val - p)))
                            }
                            _ => u,
                        };
                        color = lit(tf.lookup(level).0, p);
                        trans = 0.0;
                        break;
                    }
                    prev = Some(val);
                }
            }
            k += 1.0;
        }
        if let Mode::Mip = mode
            && max.is_finite()
        {
            let (c, op) = tf.lookup(max);
            let op = op.clamp(0.0, 1.0);
            color = c.map(|x| x * op);
            trans = 1.0 - op;
        }
        // Over an opaque black background.
        let e = |c: f64| linear_to_srgb8(c);
        let _ = trans;
        [e(color[0]), e(color[1]), e(color[2]), 255]
    })
    .unwrap()
}

fn cameras() -> Vec<Camera> {
    let v = phantom();
    let b = v.geometry().physical_bounds();
    let persp = Projection::Perspective {
        fov_y: DEFAULT_FOV_Y,
    };
    let ortho = Projection::Orthographic { view_height: 1.0 };
    vec![
        Orbit::new(30.0, 20.0, UpAxis::Z)
            .unwrap()
            .camera(b, persp, Framing::Box, 64, 48)
            .unwrap(),
        Orbit::new(-100.0, 40.0, UpAxis::Z)
            .unwrap()
            .camera(b, ortho, Framing::Box, 56, 56)
            .unwrap(),
    ]
}

fn bone() -> TransferFunction {
    TransferPreset::CtBone.build((0.0, 1.0)).unwrap()
}

#[test]
fn composite_pictures_agree_with_the_reference_ray_caster() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    for tf in [
        bone(),
        TransferPreset::CtSoftTissue.build((0.0, 1.0)).unwrap(),
    ] {
        for shading in [None, Some(Shading::default())] {
            let options = DvrOptions {
                shading,
                step: Some(0.4),
                ..DvrOptions::new(tf.clone())
            };
            let r = DvrRenderer::new(&dv, options).unwrap();
            for cam in cameras() {
                let got = r.render(&cam).unwrap();
                let want = reference(&v, &tf, shading, &cam, 0.4, Mode::Composite, None);
                let db = psnr(&got, &want).unwrap();
                assert!(
                    db >= 40.0,
                    "{:?} shading {}: PSNR {db:.1} dB",
                    tf.name(),
                    shading.is_some()
                );
                // Something is drawn.
                assert!(got.pixels().iter().any(|p| p[0] > 40), "empty picture");
            }
        }
    }
}

/// Opacity corrected for the step makes the picture a property of the volume, not of the
/// sampling: halving and quartering the step of a semi-transparent, unlit rendering changes it
/// only by the sampling error (PSNR ≥ 40 dB, total light within 2 %), whereas uncorrected
/// opacities, absorbed twice and four times as often, change the light by more than 10 %.
#[test]
fn opacity_correction_makes_pictures_independent_of_the_step() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    // Thin everywhere: most rays stay partly transparent through the whole phantom.
    let tf = TransferFunction::parse(
        "-1000:0,0,0,0; -300:1,0.7,0.5,0; 100:1,0.8,0.6,0.04; 1500:1,1,1,0.3",
    )
    .unwrap();
    let picture_with = |tf: &TransferFunction, step: f64, cam: &Camera| {
        let options = DvrOptions {
            shading: None,
            step: Some(step),
            ..DvrOptions::new(tf.clone())
        };
        DvrRenderer::new(&dv, options).unwrap().render(cam).unwrap()
    };
    let picture = |step: f64, cam: &Camera| picture_with(&tf, step, cam);
    // Uncorrected opacities: each sample absorbs the function's opacity as it is, which is the
    // corrected rendering with the unit distance equal to the step.
    let uncorrected = |step: f64, cam: &Camera| {
        picture_with(&tf.clone().with_unit_distance(step).unwrap(), step, cam)
    };
    for cam in cameras() {
        let coarse = picture(0.4, &cam);
        // Semi-transparent pixels exist, so the opacity per step matters.
        let bright = |p: &[u8; 4]| p[0].max(p[1]).max(p[2]);
        let covered = coarse.pixels().iter().filter(|p| bright(p) > 0).count();
        let partial = coarse
            .pixels()
            .iter()
            .filter(|p| (20..220).contains(&bright(p)))
            .count();
        assert!(
            partial * 2 > covered && covered > 100,
            "{partial} semi-transparent of {covered} covered pixels"
        );
        // Total light in the picture (linear), which the opacity per step scales.
        let light = |img: &RgbaImage| -> f64 {
            img.pixels()
                .iter()
                .map(|p| (0..3).map(|c| srgb8_to_linear(p[c])).sum::<f64>())
                .sum()
        };
        let (l_coarse, l_wrong) = (light(&coarse), light(&uncorrected(0.4, &cam)));
        for fine in [0.2, 0.1] {
            let fine_picture = picture(fine, &cam);
            let db = psnr(&coarse, &fine_picture).unwrap();
            assert!(db >= 40.0, "step 0.4 against {fine}: PSNR {db:.1} dB");
            let change = light(&fine_picture) / l_coarse - 1.0;
            assert!(
                change.abs() < 0.02,
                "step 0.4 against {fine}: light {change:+.3}"
            );
            // The test can tell: without the correction the light changes with the step.
            let wrong = light(&uncorrected(fine, &cam)) / l_wrong - 1.0;
            assert!(
                wrong.abs() > 0.1,
                "uncorrected step 0.4 against {fine}: light {wrong:+.3}"
            );
        }
    }
}

#[test]
fn mip_and_isosurface_agree_with_the_reference() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    let tf = TransferFunction::parse("-1000:0,0,0,0; 0:0.5,0.2,0.1,0.3; 1500:1,1,0.9,1").unwrap();
    for (mode, want_mode) in [
        (RenderMode::MaximumIntensity, Mode::Mip),
        (RenderMode::Isosurface { level: 300.0 }, Mode::Iso(300.0)),
    ] {
        let options = DvrOptions {
            mode,
            step: Some(0.3),
            ..DvrOptions::new(tf.clone())
        };
        let r = DvrRenderer::new(&dv, options).unwrap();
        for cam in cameras() {
            let got = r.render(&cam).unwrap();
            let want = reference(
                &v,
                &tf,
                Some(Shading::default()),
                &cam,
                0.3,
                want_mode,
                None,
            );
            let db = psnr(&got, &want).unwrap();
            assert!(db >= 40.0, "{mode:?}: PSNR {db:.1} dB");
        }
    }
}

#[test]
fn cut_away_removes_the_half_space() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    let centre = {
        let (lo, hi) = v.geometry().physical_bounds();
        0.5 * (lo + hi)
    };
    let clip = ClipPlane {
        point: centre,
        normal: DVec3::new(0.3, -1.0, 0.2),
    };
    let options = DvrOptions {
        clip: Some(clip),
        step: Some(0.4),
        ..DvrOptions::new(bone())
    };
    let r = DvrRenderer::new(&dv, options).unwrap();
    for cam in cameras() {
        let got = r.render(&cam).unwrap();
        let want = reference(
            &v,
            &bone(),
            Some(Shading::default()),
            &cam,
            0.4,
            Mode::Composite,
            Some(clip),
        );
        assert!(psnr(&got, &want).unwrap() >= 40.0);
        // The cut changes the picture.
        let whole = DvrRenderer::new(
            &dv,
            DvrOptions {
                step: Some(0.4),
                ..DvrOptions::new(bone())
            },
        )
        .unwrap()
        .render(&cam)
        .unwrap();
        assert_ne!(got, whole);
    }
    // A plane behind the whole volume removes nothing; one cutting away everything leaves
    // the background.
    let far = ClipPlane {
        point: centre + DVec3::splat(1e3),
        normal: DVec3::ONE,
    };
    let all = ClipPlane {
        point: centre - DVec3::splat(1e3),
        normal: DVec3::ONE,
    };
    let cam = cameras()[0];
    let plain = DvrRenderer::new(&dv, DvrOptions::new(bone()))
        .unwrap()
        .render(&cam)
        .unwrap();
    let kept = DvrRenderer::new(
        &dv,
        DvrOptions {
            clip: Some(far),
            ..DvrOptions::new(bone())
        },
    )
    .unwrap()
    .render(&cam)
    .unwrap();
    assert_eq!(kept, plain);
    let none = DvrRenderer::new(
        &dv,
        DvrOptions {
            clip: Some(all),
            ..DvrOptions::new(bone())
        },
    )
    .unwrap()
    .render(&cam)
    .unwrap();
    assert!(none.pixels().iter().all(|&p| p == [0, 0, 0, 255]));
}

/// Largest difference of any channel of any pixel.
fn max_diff(a: &RgbaImage, b: &RgbaImage) -> u8 {
    a.pixels()
        .iter()
        .zip(b.pixels())
        .flat_map(|(p, q)| (0..4).map(move |c| p[c].abs_diff(q[c])))
        .max()
        .unwrap_or(0)
}

#[test]
fn empty_space_skipping_and_early_termination_change_no_pixel_by_more_than_one_level() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    for (tf, mode) in [
        (bone(), RenderMode::Composite),
        (
            TransferPreset::CtSoftTissue.build((0.0, 1.0)).unwrap(),
            RenderMode::Composite,
        ),
        (bone(), RenderMode::MaximumIntensity),
        (bone(), RenderMode::Isosurface { level: 250.0 }),
    ] {
        let base = DvrOptions {
            mode,
            step: Some(0.35),
            ..DvrOptions::new(tf)
        };
        let plain = DvrRenderer::new(
            &dv,
            DvrOptions {
                early_termination: false,
                skip_empty_space: false,
                ..base.clone()
            },
        )
        .unwrap();
        let fast = DvrRenderer::new(&dv, base.clone()).unwrap();
        let (visible, total) = fast.visible_bricks();
        if mode != RenderMode::MaximumIntensity {
            assert!(
                visible < total,
                "{mode:?}: nothing to skip ({visible} of {total})"
            );
        }
        for cam in cameras() {
            let a = plain.render(&cam).unwrap();
            let b = fast.render(&cam).unwrap();
            assert!(
                max_diff(&a, &b) <= 1,
                "{mode:?}: {} levels",
                max_diff(&a, &b)
            );
        }
    }
}

#[test]
fn background_and_transparency() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    let cam = cameras()[0];
    let clear = DvrRenderer::new(
        &dv,
        DvrOptions {
            background: [0, 0, 0, 0],
            ..DvrOptions::new(bone())
        },
    )
    .unwrap()
    .render(&cam)
    .unwrap();
    let white = DvrRenderer::new(
        &dv,
        DvrOptions {
            background: [255, 255, 255, 255],
            ..DvrOptions::new(bone())
        },
    )
    .unwrap()
    .render(&cam)
    .unwrap();
    assert_eq!(clear.get(0, 0), Some([0, 0, 0, 0]));
    assert_eq!(white.get(0, 0), Some([255, 255, 255, 255]));
    // Straight alpha over white (in linear light) is the white-background picture.
    for (p, q) in clear.pixels().iter().zip(white.pixels()) {
        let a = f64::from(p[3]) / 255.0;
        for c in 0..3 {
            let over = srgb8_to_linear(p[c]) * a + (1.0 - a);
            assert!(
                linear_to_srgb8(over).abs_diff(q[c]) <= 2,
                "{p:?} over white vs {q:?}"
            );
        }
    }
}

#[test]
fn bad_input_is_an_error() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    let bad = [
        DvrOptions {
            step: Some(0.0),
            ..DvrOptions::new(bone())
        },
        DvrOptions {
            step: Some(f64::NAN),
            ..DvrOptions::new(bone())
        },
        DvrOptions {
            mode: RenderMode::Isosurface { level: f64::NAN },
            ..DvrOptions::new(bone())
        },
        DvrOptions {
            clip: Some(ClipPlane {
                point: DVec3::ZERO,
                normal: DVec3::ZERO,
            }),
            ..DvrOptions::new(bone())
        },
        DvrOptions {
            lut_size: 1,
            ..DvrOptions::new(bone())
        },
        DvrOptions {
            shading: Some(Shading {
                ambient: 2.0,
                ..Shading::default()
            }),
            ..DvrOptions::new(bone())
        },
    ];
    for o in bad {
        assert!(DvrRenderer::new(&dv, o).is_err());
    }
    let flat = Volume::<i16>::filled(Geometry::new([5, 1, 4]), 0).unwrap();
    assert!(DvrVolume::from_volume(&flat).is_err());
    let nan = Volume::<f32>::filled(Geometry::new([3, 3, 3]), f32::NAN).unwrap();
    assert!(DvrVolume::from_volume(&nan).is_err());
}

#[test]
fn value_coding_is_exact_for_ct_and_percentiles_come_from_the_histogram() {
    let v = phantom();
    let dv = DvrVolume::from_volume(&v).unwrap();
    let (lo, hi) = v
        .data()
        .iter()
        .fold((i16::MAX, i16::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert_eq!(dv.value_range(), (f64::from(lo), f64::from(hi)));
    let (p0, p100) = dv.percentiles(0.0, 100.0).unwrap();
    assert_eq!((p0, p100), (f64::from(lo), f64::from(hi)));
    let mut sorted: Vec<i16> = v.data().to_vec();
    sorted.sort_unstable();
    let n = sorted.len();
    let (p5, p95) = dv.percentiles(5.0, 95.0).unwrap();
    let at = |p: f64| f64::from(sorted[(p / 100.0 * (n - 1) as f64).round() as usize]);
    assert_eq!((p5, p95), (at(5.0), at(95.0)));
    assert!(dv.percentiles(50.0, 10.0).is_err());
    // Float data spanning more than 65 536 codes is coded to 1/65535 of its range.
    let f = Volume::<f32>::from_fn(Geometry::new([4, 4, 4]), |i, j, k| {
        (i * 16 + j * 4 + k) as f32 * 1234.567
    })
    .unwrap();
    let df = DvrVolume::from_volume(&f).unwrap();
    assert_eq!(df.value_range().0, 0.0);
    assert!((df.value_range().1 - 63.0 * 1234.567).abs() < 1e-2);
}

mod deformed {
    use super::*;
    use volmorph_deform::{Identity, SpaceMap};
    use volmorph_render::DeformedView;

    /// A smooth pull-back: a bend and a twist about the volume's centre.
    struct Bend {
        centre: DVec3,
    }

    impl SpaceMap for Bend {
        fn apply(&self, p: DVec3) -> DVec3 {
            let q = p - self.centre;
            let a = 0.04 * q.z;
            let (s, c) = a.sin_cos();
            self.centre
                + DVec3::new(
                    c * q.x - s * q.y + 1.5 * (q.z / 6.0).sin(),
                    s * q.x + c * q.y,
                    q.z,
                )
        }
    }

    #[test]
    fn identity_map_renders_the_undeformed_picture() {
        let v = phantom();
        let dv = DvrVolume::from_volume(&v).unwrap();
        for mode in [
            RenderMode::Composite,
            RenderMode::MaximumIntensity,
            RenderMode::Isosurface { level: 300.0 },
        ] {
            let r = DvrRenderer::new(
                &dv,
                DvrOptions {
                    mode,
                    step: Some(0.4),
                    ..DvrOptions::new(bone())
                },
            )
            .unwrap();
            for nodes in [[2, 2, 2], [9, 7, 5]] {
                let view = DeformedView::from_map(&dv, &Identity, nodes).unwrap();
                for cam in cameras() {
                    let plain = r.render(&cam).unwrap();
                    let deformed = r.render_deformed(&view, &cam).unwrap();
                    let diff = max_diff(&plain, &deformed);
                    let same = plain
                        .pixels()
                        .iter()
                        .zip(deformed.pixels())
                        .filter(|(a, b)| a == b)
                        .count();
                    assert!(diff <= 1, "{mode:?} {nodes:?}: {diff} levels");
                    assert!(
                        same * 100 >= 99 * plain.pixels().len(),
                        "{mode:?}: {same} equal pixels"
                    );
                }
            }
        }
    }

    #[test]
    fn a_translation_shows_the_volume_moved_the_other_way() {
        let v = phantom();
        let dv = DvrVolume::from_volume(&v).unwrap();
        let s = DVec3::new(1.5, -1.0, 0.7);
        struct Shift(DVec3);
        impl SpaceMap for Shift {
            fn apply(&self, p: DVec3) -> DVec3 {
                p + self.0
            }
        }
        let view = DeformedView::from_map(&dv, &Shift(s), [5, 5, 5]).unwrap();
        // The same content with its origin moved by −s.
        let mut moved = v.clone();
        let g = *v.geometry();
        moved.set_geometry(g.with_origin(g.origin - s)).unwrap();
        let dm = DvrVolume::from_volume(&moved).unwrap();
        let opts = DvrOptions {
            step: Some(0.4),
            ..DvrOptions::new(bone())
        };
        let r = DvrRenderer::new(&dv, opts.clone()).unwrap();
        let rm = DvrRenderer::new(&dm, opts).unwrap();
        for cam in cameras() {
            let a = r.render_deformed(&view, &cam).unwrap();
            let b = rm.render(&cam).unwrap();
            let db = psnr(&a, &b).unwrap();
            assert!(db >= 40.0, "PSNR {db:.1}");
            assert_ne!(
                a,
                r.render(&cam).unwrap(),
                "the translation changes the picture"
            );
        }
    }

    #[test]
    fn a_bent_volume_agrees_with_the_reference_through_the_exact_map() {
        let v = phantom();
        let dv = DvrVolume::from_volume(&v).unwrap();
        let g = *v.geometry();
        let (lo, hi) = g.physical_bounds();
        let bend = Bend {
            centre: 0.5 * (lo + hi),
        };
        let view = DeformedView::from_map(&dv, &bend, g.dims).unwrap();
        let tf = bone();
        let step = 0.4;
        let r = DvrRenderer::new(
            &dv,
            DvrOptions {
                step: Some(step),
                ..DvrOptions::new(tf.clone())
            },
        )
        .unwrap();
        let a = g.index_to_physical_matrix();
        let a_inv = a.inverse();
        let shading = Shading::default();
        for cam in cameras() {
            let got = r.render_deformed(&view, &cam).unwrap();
            let lit = shading.for_camera(&cam).unwrap();
            let want = RgbaImage::from_fn(cam.width(), cam.height(), |x, y| {
                let ray = cam.ray(x, y);
                let o = g.physical_to_index(ray.origin);
                let d = a_inv * ray.dir;
                let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                for ax in 0..3 {
                    let n = (g.dims[ax] - 1) as f64;
                    if d[ax] == 0.0 {
                        if o[ax] < 0.0 || o[ax] > n {
                            return [0, 0, 0, 255];
                        }
                        continue;
                    }
                    let (ta, tb) = (-o[ax] / d[ax], (n - o[ax]) / d[ax]);
                    t0 = t0.max(ta.min(tb));
                    t1 = t1.min(ta.max(tb));
                }
                let (mut color, mut trans) = ([0.0f64; 3], 1.0f64);
                let mut k = (t0 / step).ceil();
                while k * step < t1 {
                    let x = ray.at(k * step);
                    let u = g.physical_to_index(bend.apply(x));
                    k += 1.0;
                    let n = (0..3).all(|ax| u[ax] >= 0.0 && u[ax] <= (g.dims[ax] - 1) as f64);
                    if !n {
                        continue;
                    }
                    let (c, op) = tf.lookup(trilinear(&v, u));
                    let alpha = corrected_opacity(op, step, tf.unit_distance());
                    if alpha > 0.0 {
                        let gu = DVec3::new(
                            trilinear(&v, u + DVec3::X) - trilinear(&v, u - DVec3::X),
                            trilinear(&v, u + DVec3::Y) - trilinear(&v, u - DVec3::Y),
                            trilinear(&v, u + DVec3::Z) - trilinear(&v, u - DVec3::Z),
                        ) * 0.5;
                        // ∇ₓ V(A⁻¹(bend(x) − o)) = Jᵀ A⁻ᵀ ∇ᵤV.
                        let grad = bend.jacobian(x).transpose() * (a_inv.transpose() * gu);
                        let c = lit.shade(c, grad, -ray.dir);
                        for ch in 0..3 {
                            color[ch] += trans * alpha * c[ch];
                        }
                        trans *= 1.0 - alpha;
                    }
                }
                [
                    linear_to_srgb8(color[0]),
                    linear_to_srgb8(color[1]),
                    linear_to_srgb8(color[2]),
                    255,
                ]
            })
            .unwrap();
            let db = psnr(&got, &want).unwrap();
            assert!(db >= 35.0, "PSNR {db:.1}");
            assert_ne!(got, r.render(&cam).unwrap(), "the bend changes the picture");
        }
    }

    /// Grid sizes of the PSNR study, coarse to fine.
    const PSNR_GRIDS: [usize; 6] = [2, 3, 5, 9, 17, 33];

    /// The 40 dB agreement of the issue (McPhail §5.5.1: the coarse map is "visually
    /// indistinguishable"), which the study's grid must reach.
    const TARGET_DB: f64 = 40.0;

    /// A 200-handle affine MLS pull-back bending the phantom by a few per cent of its size.
    fn mls200(g: &Geometry) -> volmorph_handles::AffineMls {
        let (lo, hi) = g.physical_bounds();
        let (c, e) = (0.5 * (lo + hi), hi - lo);
        let mut rng = volmorph_testkit::Rng::new(20_241_201);
        let sources: Vec<DVec3> = (0..200).map(|_| rng.point_in(lo, hi)).collect();
        let targets: Vec<DVec3> = sources
            .iter()
            .map(|&s| {
                let q = (s - c) / e;
                s + DVec3::new(
                    0.06 * e.x * (q.z * std::f64::consts::PI).sin(),
                    0.05 * e.y * (q.x * std::f64::consts::PI).cos(),
                    0.0,
                )
            })
            .collect();
        volmorph_handles::AffineMls::new(
            &targets,
            &sources,
            volmorph_handles::Weighting::InverseDistance { alpha: 1.0 },
        )
        .unwrap()
    }

    /// PSNR of the picture through the map sampled on an n³ grid against the picture of the
    /// fully resampled volume (every voxel of a three-times-finer grid pulled back through the
    /// exact map), per grid size: it must rise with the grid, stay below 40 dB on the
    /// coarsest grid (so the grid matters) and reach 40 dB by 33³. Unlit, as the resampled
    /// volume's gradients are differences of re-interpolated voxels, not the deformed
    /// field's.
    #[test]
    fn coarse_grid_psnr_rises_with_the_grid_and_reaches_40_db() {
        use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
        let v = phantom();
        let g = *v.geometry();
        let map = mls200(&g);
        // The reference grid: the same box, three times as many cells per axis.
        let fine = Geometry {
            dims: g.dims.map(|d| 3 * d - 2),
            spacing: g.spacing / 3.0,
            ..g
        };
        let options = WarpOptions {
            background: -1000.0,
            mask: false,
            sampled_nodes: None,
        };
        let resampled = warp_volume(
            &v.clone().into(),
            &map,
            &fine,
            WarpMethod::PullbackLinear,
            &options,
        )
        .unwrap();
        let dv = DvrVolume::from_volume(&v).unwrap();
        let dr = DvrVolume::new(&resampled.volume).unwrap();
        let opts = DvrOptions {
            step: Some(0.4),
            shading: None,
            ..DvrOptions::new(bone())
        };
        let r = DvrRenderer::new(&dv, opts.clone()).unwrap();
        let rr = DvrRenderer::new(&dr, opts).unwrap();
        for cam in cameras() {
            let reference = rr.render(&cam).unwrap();
            let db: Vec<f64> = PSNR_GRIDS
                .iter()
                .map(|&n| {
                    let view = DeformedView::from_map(&dv, &map, [n; 3]).unwrap();
                    psnr(&r.render_deformed(&view, &cam).unwrap(), &reference).unwrap()
                })
                .collect();
            eprintln!("PSNR per grid {PSNR_GRIDS:?}: {db:.1?} dB");
            for w in db.windows(2) {
                // Rising, up to the small noise of the reference's own resampling.
                assert!(w[1] >= w[0] - 0.5, "PSNR per grid {PSNR_GRIDS:?}: {db:.1?}");
            }
            assert!(
                db[0] < TARGET_DB,
                "the 2³ grid already gives {:.1} dB",
                db[0]
            );
            let reached = PSNR_GRIDS.iter().zip(&db).find(|(_, d)| **d >= TARGET_DB);
            assert!(
                reached.is_some(),
                "40 dB not reached by 33³: {PSNR_GRIDS:?} → {db:.1?}"
            );
        }
    }

    #[test]
    fn a_view_for_another_volume_is_refused() {
        let v = phantom();
        let dv = DvrVolume::from_volume(&v).unwrap();
        let other =
            DvrVolume::from_volume(&Volume::<i16>::filled(Geometry::new([4, 4, 4]), 0).unwrap())
                .unwrap();
        let view = DeformedView::from_map(&other, &Identity, [3, 3, 3]).unwrap();
        let r = DvrRenderer::new(&dv, DvrOptions::new(bone())).unwrap();
        assert!(r.render_deformed(&view, &cameras()[0]).is_err());
        assert!(DeformedView::from_map(&dv, &Identity, [1, 3, 3]).is_err());
    }
}

mod quality {
    use super::*;
    use volmorph_deform::Identity;
    use volmorph_render::{DeformedView, QualityOptions, render_quality};

    /// The phantom with an extra bright ball (a "target" brighter than the source there).
    fn brighter() -> Volume<i16> {
        let mut v = phantom();
        let g = *v.geometry();
        let c = g.index_to_physical(DVec3::new(8.0, 8.0, 6.0));
        for k in 0..g.dims[2] {
            for j in 0..g.dims[1] {
                for i in 0..g.dims[0] {
                    let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    if (p - c).length() < 3.0 {
                        *v.get_mut(i, j, k).unwrap() += 900;
                    }
                }
            }
        }
        v
    }

    fn options() -> QualityOptions {
        QualityOptions {
            step: Some(0.4),
            // One window for both, so that equal values give equal intensities.
            source_window: Some(volmorph_render::Window::from_range(-1000.0, 2500.0).unwrap()),
            target_window: Some(volmorph_render::Window::from_range(-1000.0, 2500.0).unwrap()),
            ..QualityOptions::default()
        }
    }

    /// Regression: the quality view's opacities were per millimetre, so a volume a few units
    /// across (a phantom in unit coordinates) came out almost black. They now scale with the
    /// volume: shrinking the geometry (and the step with it) keeps the picture.
    #[test]
    fn quality_view_of_a_small_volume_is_not_dim() {
        let big = phantom();
        let mut small = big.clone();
        let g = *big.geometry();
        let k = 0.05;
        small
            .set_geometry(g.with_spacing(g.spacing * k).with_origin(g.origin * k))
            .unwrap();
        let pictures = [(&big, 1.0), (&small, k)].map(|(v, scale)| {
            let dv = DvrVolume::from_volume(v).unwrap();
            let view =
                DeformedView::from_map_over(&dv, &Identity, dv.geometry(), [5, 5, 5]).unwrap();
            let cam = Orbit::new(30.0, 20.0, UpAxis::Z)
                .unwrap()
                .camera(
                    dv.geometry().physical_bounds(),
                    Projection::Perspective {
                        fov_y: DEFAULT_FOV_Y,
                    },
                    Framing::Sphere,
                    48,
                    48,
                )
                .unwrap();
            let o = QualityOptions {
                step: Some(0.4 * scale),
                ..options()
            };
            render_quality(&dv, &dv, &view, &cam, &o).unwrap()
        });
        assert!(max_diff(&pictures[0], &pictures[1]) <= 1);
        let greenest = pictures[1].pixels().iter().map(|p| p[1]).max().unwrap();
        assert!(greenest > 60, "matched material glows dimly: {greenest}");
    }

    #[test]
    fn identical_volumes_are_green_and_differences_red_or_blue() {
        let s = DvrVolume::from_volume(&phantom()).unwrap();
        let t = DvrVolume::from_volume(&brighter()).unwrap();
        let cam = cameras()[0];
        let view_ss = DeformedView::from_map_over(&s, &Identity, s.geometry(), [5, 5, 5]).unwrap();
        let same = render_quality(&s, &s, &view_ss, &cam, &options()).unwrap();
        assert!(
            same.pixels().iter().all(|p| p[0] <= 1 && p[2] <= 1),
            "matching volumes show red or blue"
        );
        assert!(
            same.pixels().iter().any(|p| p[1] > 30),
            "matching volumes show no green"
        );
        // The target is brighter in a ball: blue there; swapped, red (symmetry).
        let view_st = DeformedView::from_map_over(&t, &Identity, s.geometry(), [5, 5, 5]).unwrap();
        let st = render_quality(&s, &t, &view_st, &cam, &options()).unwrap();
        let view_ts = DeformedView::from_map_over(&s, &Identity, t.geometry(), [5, 5, 5]).unwrap();
        let ts = render_quality(&t, &s, &view_ts, &cam, &options()).unwrap();
        let bluest = st.pixels().iter().max_by_key(|p| p[2]).unwrap();
        assert!(bluest[2] > 60, "no blue difference: {bluest:?}");
        assert!(
            st.pixels().iter().all(|p| p[0] <= 1),
            "red where the source is never brighter"
        );
        for (a, b) in st.pixels().iter().zip(ts.pixels()) {
            assert!(
                a[0].abs_diff(b[2]) <= 1 && a[2].abs_diff(b[0]) <= 1 && a[1].abs_diff(b[1]) <= 1,
                "{a:?} vs {b:?}"
            );
        }
        // Culling and early termination move no channel by more than one level.
        let slow = render_quality(
            &s,
            &t,
            &view_st,
            &cam,
            &QualityOptions {
                skip_empty_space: false,
                early_termination: false,
                ..options()
            },
        )
        .unwrap();
        assert!(max_diff(&slow, &st) <= 1);
        // Bad options.
        assert!(
            render_quality(
                &s,
                &t,
                &view_st,
                &cam,
                &QualityOptions {
                    threshold: 1.0,
                    ..options()
                }
            )
            .is_err()
        );
    }
}
