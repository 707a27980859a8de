//! Test data with known answers: a breathing lung phantom and known smooth deformations of any
//! volume.
//!
//! # The lung phantom ([`lung_phantom`])
//!
//! A thorax in LPS coordinates (x to the patient's left, y posterior, z superior; the grid is
//! centred on the origin): air outside an elliptic body of soft tissue (40 HU), six pairs of
//! ribs (bone, 700 HU) near the body wall, a vertebral column (500 HU with a 900 HU cortex)
//! behind the mediastinum, and two lungs (parenchyma −850 HU) with domed bases. A trachea
//! (air lumen, −1000 HU) descends from the top of the volume, splits at the carina into two
//! main bronchi that enter the lungs, and each lung holds a branching vessel tree (+40 HU,
//! radii shrinking by 0.75 per generation) and a shorter airway tree (air lumen in a −300 HU
//! wall). Five lobes are separated by thin fissure sheets (peak −720 HU, Gaussian profile of
//! half a voxel): the right oblique fissure (lower lobe posterior-inferior), the right
//! horizontal fissure (middle lobe anterior-inferior, present anterior of the oblique one) and
//! the left oblique fissure. Gaussian noise of `noise` HU is added to every voxel.
//!
//! The exhale scan is the inhale scan moved by a known smooth [`BreathingMotion`] `φ`
//! (inhale point → exhale point): the base rises most (diaphragm), the chest contracts
//! front-to-back and sideways, all fading outside the thorax. Each exhale voxel `y` shows the
//! noise-free inhale at `φ⁻¹(y)` (Newton inversion), and the lung parenchyma's density follows
//! mass conservation: `HU_ex = (1000 + HU_in)/det Dφ − 1000`. Ground-truth landmark pairs are the
//! vessel bifurcations `b` and `φ(b)`. The true lobe labels and a scripted lobe-tracing input
//! (the fissures' end points on the lung boundary at every few axial sections,
//! [`crate::lungs::LobeScript`]) come with it, so the lobe model can be checked.
//!
//! # Known deformations of any volume ([`known_deformation`])
//!
//! A cubic B-spline lattice over the volume with random control displacements (uniform in a
//! ball of the given magnitude, outer three layers fixed so the field is smooth and vanishes at
//! the border), and optionally an intensity change (gain, offset, smooth multiplicative bias
//! field and gamma) for an inter-subject-like pair. The moving volume is the input pulled back
//! through the inverse of the field, so the field maps fixed points to moving points like every
//! map in this crate.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::inverse::{InverseResampleOptions, pullback_through_inverse};

use crate::RegisterError;
use crate::lungs::{FissureKind, FissureScript, KeyPoints, LobeScript};
use crate::noise::{self, Stream};

/// Lobe labels of the lung model and the phantom.
pub mod lobe {
    /// Not a lung voxel.
    pub const NONE: u8 = 0;
    /// Right upper lobe.
    pub const RUL: u8 = 1;
    /// Right middle lobe.
    pub const RML: u8 = 2;
    /// Right lower lobe.
    pub const RLL: u8 = 3;
    /// Left upper lobe.
    pub const LUL: u8 = 4;
    /// Left lower lobe.
    pub const LLL: u8 = 5;
    /// Names, indexed by label.
    pub const NAMES: [&str; 6] = ["none", "RUL", "RML", "RLL", "LUL", "LLL"];
}

/// HU of air.
pub const HU_AIR: f32 = -1000.0;
/// HU of lung parenchyma at inhale.
pub const HU_PARENCHYMA: f32 = -850.0;
/// Peak HU of a fissure sheet.
pub const HU_FISSURE: f32 = -720.0;
/// HU of soft tissue and blood.
pub const HU_SOFT: f32 = 40.0;
/// HU of rib bone.
pub const HU_BONE: f32 = 700.0;

/// Options of [`lung_phantom`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LungPhantomOptions {
    /// Voxels per axis.
    pub dims: [usize; 3],
    /// Voxel spacing, mm.
    pub spacing: DVec3,
    /// Noise standard deviation, HU.
    pub noise: f64,
    /// Superior motion of the lung base at exhale, mm.
    pub amplitude: f64,
    /// Seed of the vessel trees and the noise.
    pub seed: u64,
    /// Vessel tree generations.
    pub generations: usize,
}

impl Default for LungPhantomOptions {
    fn default() -> Self {
        Self {
            dims: [96, 80, 72],
            spacing: DVec3::new(3.0, 3.0, 3.5),
            noise: 15.0,
            amplitude: 18.0,
            seed: 1,
            generations: 6,
        }
    }
}

/// The known breathing motion `φ`: inhale point → exhale point (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BreathingMotion {
    /// Superior motion of the base, mm.
    pub amplitude: f64,
    /// Height (mm) about which the motion fades from base to apex.
    pub z_mid: f64,
    /// Length (mm) of that fade.
    pub fade: f64,
    /// Front-to-back contraction (fraction of `y`).
    pub ap: f64,
    /// Side-to-side contraction (fraction of `x`).
    pub lateral: f64,
    /// Radii of the thorax envelope in x and y, mm.
    pub envelope: [f64; 2],
}

impl BreathingMotion {
    /// The envelope `e = exp(−(x/a)² − (y/b)²)` and the base-to-apex fade
    /// `s = 1 / (1 + exp((z − z_mid)/fade))` at `p`.
    fn factors(&self, p: DVec3) -> (f64, f64) {
        let e = (-(p.x / self.envelope[0]).powi(2) - (p.y / self.envelope[1]).powi(2)).exp();
        let s = 1.0 / (1.0 + ((p.z - self.z_mid) / self.fade).exp());
        (e, s)
    }

    /// The displacement at `p`, given its [`factors`](Self::factors) `(e, s)`.
    fn displacement(&self, p: DVec3, (e, s): (f64, f64)) -> DVec3 {
        DVec3::new(
            -self.lateral * p.x * e * (0.5 + 0.5 * s),
            -self.ap * p.y * e * s,
            self.amplitude * e * s,
        )
    }
}

impl SpaceMap for BreathingMotion {
    fn apply(&self, p: DVec3) -> DVec3 {
        p + self.displacement(p, self.factors(p))
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.apply_with_jacobian(p).1
    }

    /// Analytic: with `∂e/∂x = −2x e/a²`, `∂e/∂y = −2y e/b²` and `∂s/∂z = −s(1 − s)/fade`
    /// (the logistic's derivative; `0` where `s` saturates), the displacement's partial
    /// derivatives added to the identity. The two exponentials are taken once for both.
    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        let (e, s) = self.factors(p);
        let [a, b] = self.envelope;
        let (ex, ey) = (-2.0 * p.x / (a * a) * e, -2.0 * p.y / (b * b) * e);
        let sz = -s * (1.0 - s) / self.fade;
        let h = 0.5 + 0.5 * s;
        let (l, ap, amp) = (self.lateral, self.ap, self.amplitude);
        // Columns ∂/∂x, ∂/∂y, ∂/∂z of (d_x, d_y, d_z).
        let dx = DVec3::new(-l * h * (e + p.x * ex), -ap * p.y * s * ex, amp * s * ex);
        let dy = DVec3::new(-l * p.x * h * ey, -ap * s * (e + p.y * ey), amp * s * ey);
        let dz = DVec3::new(-l * p.x * e * 0.5 * sz, -ap * p.y * e * sz, amp * e * sz);
        (
            p + self.displacement(p, (e, s)),
            DMat3::IDENTITY + DMat3::from_cols(dx, dy, dz),
        )
    }
}

/// Shape parameters of the thorax (mm), derived from the grid extent.
#[derive(Debug, Clone, Copy)]
struct Anatomy {
    body: [f64; 2],
    lung_c: [DVec3; 2],
    lung_r: DVec3,
    base_z: f64,
    dome: f64,
    spine: (DVec3, f64),
    trachea_r: f64,
    carina: DVec3,
    hilum: [DVec3; 2],
    oblique_slope: f64,
    oblique_z: f64,
    horizontal_slope: f64,
    horizontal_z: f64,
}

impl Anatomy {
    fn of(g: &Geometry) -> Self {
        let (lo, hi) = g.physical_bounds();
        let ext = hi - lo;
        let body = [0.45 * ext.x, 0.42 * ext.y];
        let lung_r = DVec3::new(0.36 * body[0], 0.72 * body[1], 0.40 * ext.z);
        let cz = 0.0;
        let lung_c = [
            DVec3::new(-0.46 * body[0], 0.0, cz),
            DVec3::new(0.46 * body[0], 0.0, cz),
        ];
        let base_z = cz - 0.62 * lung_r.z;
        Self {
            body,
            lung_c,
            lung_r,
            base_z,
            dome: 0.25 * lung_r.z,
            spine: (DVec3::new(0.0, 0.78 * body[1], 0.0), 0.12 * body[0]),
            trachea_r: 0.05 * body[0].max(12.0),
            carina: DVec3::new(0.0, -0.05 * body[1], cz + 0.45 * lung_r.z),
            hilum: [
                DVec3::new(-0.30 * body[0], 0.0, cz + 0.15 * lung_r.z),
                DVec3::new(0.30 * body[0], 0.0, cz + 0.15 * lung_r.z),
            ],
            oblique_slope: 0.9,
            oblique_z: cz - 0.05 * lung_r.z,
            horizontal_slope: -0.8,
            horizontal_z: cz + 0.05 * lung_r.z,
        }
    }

    /// Which lung (0 right, 1 left) contains `p`, if any.
    fn lung(&self, p: DVec3) -> Option<usize> {
        for (s, c) in self.lung_c.iter().enumerate() {
            let q = (p - *c) / self.lung_r;
            let r2 = q.length_squared();
            let floor = self.base_z + self.dome * (1.0 - q.x * q.x - q.y * q.y).max(0.0);
            if r2 <= 1.0 && p.z >= floor {
                return Some(s);
            }
        }
        None
    }

    /// The oblique fissure's y at height z in lung `s` (posterior of it: lower lobe).
    fn oblique_y(&self, s: usize, z: f64) -> f64 {
        self.lung_c[s].y + self.oblique_slope * (z - self.oblique_z)
    }

    /// The horizontal fissure's y at height z (anterior of it: middle lobe).
    fn horizontal_y(&self, z: f64) -> f64 {
        self.lung_c[0].y + (z - self.horizontal_z) / self.horizontal_slope
    }

    /// True lobe label of a lung point.
    fn lobe_of(&self, p: DVec3) -> u8 {
        match self.lung(p) {
            None => lobe::NONE,
            Some(0) => {
                if p.y > self.oblique_y(0, p.z) {
                    lobe::RLL
                } else if p.y < self.horizontal_y(p.z) {
                    lobe::RML
                } else {
                    lobe::RUL
                }
            }
            Some(_) => {
                if p.y > self.oblique_y(1, p.z) {
                    lobe::LLL
                } else {
                    lobe::LUL
                }
            }
        }
    }

    /// Distance (mm) to the nearest fissure sheet of a lung point (∞ if none applies).
    fn fissure_distance(&self, p: DVec3, s: usize) -> f64 {
        let n = (1.0 + self.oblique_slope * self.oblique_slope).sqrt();
        let d_ob = (p.y - self.oblique_y(s, p.z)).abs() / n;
        if s == 1 {
            return d_ob;
        }
        // Horizontal sheet only anterior of the oblique one.
        let d_h = if p.y < self.oblique_y(0, p.z) {
            let m = (1.0 + 1.0 / (self.horizontal_slope * self.horizontal_slope)).sqrt();
            (p.y - self.horizontal_y(p.z)).abs() / m
        } else {
            f64::INFINITY
        };
        d_ob.min(d_h)
    }
}

/// A tube segment `a → b` of radius `r`.
#[derive(Debug, Clone, Copy)]
struct Segment {
    a: DVec3,
    b: DVec3,
    r: f64,
}

/// Grow a branching tree from `root` along `dir`; returns segments and bifurcation points
/// (with the parent radius).
#[allow(clippy::too_many_arguments)]
fn grow_tree(
    anat: &Anatomy,
    lung: usize,
    root: DVec3,
    dir: DVec3,
    length: f64,
    radius: f64,
    generations: usize,
    rng: &mut Stream,
) -> (Vec<Segment>, Vec<(DVec3, f64)>) {
    let mut segs = Vec::new();
    let mut forks = Vec::new();
    let mut stack = vec![(root, dir.normalize(), length, radius, 0usize)];
    while let Some((a, d, len, r, gen_)) = stack.pop() {
        let b = a + d * len;
        if anat.lung(b) != Some(lung) && gen_ > 0 {
            continue;
        }
        segs.push(Segment { a, b, r });
        if gen_ + 1 >= generations {
            continue;
        }
        forks.push((b, r));
        // Two children at ±(25…40)° in a random plane containing d.
        let any = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let u = d.cross(any).normalize();
        let v = d.cross(u);
        let phi = rng.range(0.0, std::f64::consts::TAU);
        let axis = u * phi.cos() + v * phi.sin();
        for sign in [1.0, -1.0] {
            let ang = sign * rng.range(25f64.to_radians(), 40f64.to_radians());
            let nd = (d * ang.cos() + axis * ang.sin()).normalize();
            stack.push((b, nd, len * rng.range(0.7, 0.85), r * 0.75, gen_ + 1));
        }
    }
    (segs, forks)
}

/// Distance from `p` to segment `s`.
fn segment_distance(p: DVec3, s: &Segment) -> f64 {
    let ab = s.b - s.a;
    let t = ((p - s.a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
    (p - (s.a + ab * t)).length()
}

/// Draw tubes into `data` (value `hu` inside radius `r + extra`, partial volume over one voxel).
fn draw_tubes(data: &mut [f32], g: &Geometry, segs: &[Segment], extra: f64, hu: f32) {
    let inv = g.index_to_physical_matrix().inverse();
    let h = g.spacing.element_sum() / 3.0;
    let [nx, ny, nz] = g.dims;
    for s in segs {
        let r = s.r + extra;
        let lo = s.a.min(s.b) - DVec3::splat(r + 2.0 * h);
        let hi = s.a.max(s.b) + DVec3::splat(r + 2.0 * h);
        let (il, ih) = (inv * (lo - g.origin), inv * (hi - g.origin));
        let (a, b) = (il.min(ih), il.max(ih));
        let range = |x: f64, y: f64, n: usize| {
            let l = x.floor().max(0.0) as usize;
            let u = (y.ceil().max(0.0) as usize).min(n.saturating_sub(1));
            l..=u
        };
        for k in range(a.z, b.z, nz) {
            for j in range(a.y, b.y, ny) {
                for i in range(a.x, b.x, nx) {
                    let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    let d = segment_distance(p, s);
                    let alpha = ((r - d) / h + 0.5).clamp(0.0, 1.0) as f32;
                    if alpha > 0.0 {
                        let o = i + nx * (j + ny * k);
                        data[o] += (hu - data[o]) * alpha;
                    }
                }
            }
        }
    }
}

/// The phantom (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct LungPhantom {
    /// Inhale scan (fixed), HU.
    pub inhale: Volume<f32>,
    /// Exhale scan (moving), HU.
    pub exhale: Volume<f32>,
    /// True lobe labels on the inhale grid ([`lobe`]).
    pub lobes: Volume<u8>,
    /// The known motion, inhale → exhale.
    pub motion: BreathingMotion,
    /// Landmarks (vessel bifurcations) in the inhale scan.
    pub landmarks_inhale: Vec<DVec3>,
    /// The same landmarks in the exhale scan, `φ(b)`.
    pub landmarks_exhale: Vec<DVec3>,
    /// Scripted input of the lobe tracing.
    pub lobe_script: LobeScript,
}

/// Generate the phantom (see the [module docs](self)).
///
/// # Errors
/// [`RegisterError::Option`] for fewer than 32 voxels along an axis or a bad spacing,
/// [`RegisterError::Warp`] if the exhale resampling fails.
pub fn lung_phantom(o: &LungPhantomOptions) -> Result<LungPhantom, RegisterError> {
    if o.dims.iter().any(|&n| !(32..=1024).contains(&n)) {
        return Err(RegisterError::option(
            "dims",
            "every axis needs 32…1024 voxels",
        ));
    }
    crate::error::positive("spacing", o.spacing.min_element())?;
    crate::error::non_negative("noise", o.noise)?;
    let ext = o.spacing
        * DVec3::new(
            (o.dims[0] - 1) as f64,
            (o.dims[1] - 1) as f64,
            (o.dims[2] - 1) as f64,
        );
    let g = Geometry::new(o.dims)
        .with_spacing(o.spacing)
        .with_origin(-0.5 * ext);
    let anat = Anatomy::of(&g);
    let n = g.len();
    // Static anatomy and lobes.
    let mut clean = vec![0.0f32; n];
    let mut lobes = vec![0u8; n];
    let h = o.spacing.element_sum() / 3.0;
    let rib_z: Vec<f64> = (0..6)
        .map(|i| anat.base_z + (i as f64 + 0.5) * (anat.lung_r.z * 1.7) / 6.0)
        .collect();
    let rib_r = (0.035 * anat.body[0]).max(1.2 * h);
    clean
        .par_chunks_mut(o.dims[0] * o.dims[1])
        .zip(lobes.par_chunks_mut(o.dims[0] * o.dims[1]))
        .enumerate()
        .for_each(|(k, (slab, lslab))| {
            for j in 0..o.dims[1] {
                for i in 0..o.dims[0] {
                    let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    let e = (p.x / anat.body[0]).powi(2) + (p.y / anat.body[1]).powi(2);
                    let mut v = if e <= 1.0 { HU_SOFT } else { HU_AIR };
                    // Ribs: tubes along the body wall at fixed heights, posterior two thirds.
                    let wall = e.sqrt();
                    for &z in &rib_z {
                        let dz = p.z - z + 0.25 * p.y.max(0.0);
                        let dr = (wall - 0.9) * anat.body[0].min(anat.body[1]);
                        if (dz * dz + dr * dr).sqrt() < rib_r && p.y > -0.5 * anat.body[1] {
                            v = HU_BONE;
                        }
                    }
                    let (sc, sr) = anat.spine;
                    let ds = ((p.x - sc.x).powi(2) + (p.y - sc.y).powi(2)).sqrt();
                    if ds < sr {
                        v = if ds > 0.8 * sr { 900.0 } else { 500.0 };
                    }
                    if let Some(s) = anat.lung(p) {
                        v = HU_PARENCHYMA;
                        let d = anat.fissure_distance(p, s);
                        let sigma = 0.5 * h;
                        v += (HU_FISSURE - HU_PARENCHYMA)
                            * (-(d * d) / (2.0 * sigma * sigma)).exp() as f32;
                        lslab[i + o.dims[0] * j] = anat.lobe_of(p);
                    }
                    slab[i + o.dims[0] * j] = v;
                }
            }
        });
    // Airways: trachea and main bronchi (wall then lumen), airway trees in the lungs.
    let mut rng = Stream::new(o.seed);
    let top = DVec3::new(0.0, anat.carina.y, g.physical_bounds().1.z + 2.0 * h);
    let main = [
        Segment {
            a: top,
            b: anat.carina,
            r: anat.trachea_r,
        },
        Segment {
            a: anat.carina,
            b: anat.hilum[0],
            r: 0.7 * anat.trachea_r,
        },
        Segment {
            a: anat.carina,
            b: anat.hilum[1],
            r: 0.7 * anat.trachea_r,
        },
    ];
    draw_tubes(&mut clean, &g, &main, 0.3 * anat.trachea_r, HU_SOFT);
    draw_tubes(&mut clean, &g, &main, 0.0, HU_AIR);
    let mut landmarks = Vec::new();
    for s in 0..2 {
        let out = DVec3::new(if s == 0 { -1.0 } else { 1.0 }, 0.0, -0.6);
        let (air, _) = grow_tree(
            &anat,
            s,
            anat.hilum[s],
            out,
            0.3 * anat.lung_r.z,
            0.5 * anat.trachea_r,
            3,
            &mut rng,
        );
        draw_tubes(&mut clean, &g, &air, 0.5 * h, -300.0);
        draw_tubes(&mut clean, &g, &air, 0.0, HU_AIR);
        for (dir, len) in [
            (DVec3::new(0.3 * out.x, -0.4, -1.0), 0.32),
            (DVec3::new(0.3 * out.x, 0.5, 0.9), 0.28),
            (DVec3::new(out.x, 0.2, -0.1), 0.25),
        ] {
            let (vs, forks) = grow_tree(
                &anat,
                s,
                anat.hilum[s] + DVec3::new(0.0, 0.08 * anat.lung_r.y, 0.0),
                dir,
                len * anat.lung_r.z,
                (0.045 * anat.body[0]).max(1.6 * h),
                o.generations,
                &mut rng,
            );
            draw_tubes(&mut clean, &g, &vs, 0.0, HU_SOFT);
            for (b, r) in forks {
                if r >= 0.6 * h && anat.lung(b) == Some(s) {
                    landmarks.push(b);
                }
            }
        }
    }
    let inhale_clean = Volume::new(g, clean)?;
    let motion = BreathingMotion {
        amplitude: o.amplitude,
        z_mid: anat.lung_c[0].z - 0.1 * anat.lung_r.z,
        fade: 0.3 * anat.lung_r.z,
        ap: 0.04,
        lateral: 0.02,
        envelope: [1.3 * anat.body[0], 1.3 * anat.body[1]],
    };
    // Exhale: noise-free inhale at φ⁻¹(y), densities by mass conservation.
    let det = volmorph_warp::jacobian::jacobian_determinant(&motion, &g)?;
    let opts = InverseResampleOptions::new(Interpolation::Linear, f64::from(HU_AIR));
    let ex: Volume<f32> = pullback_through_inverse(&inhale_clean, &motion, &g, &opts)?.volume;
    let ex_det: Volume<f32> = pullback_through_inverse(
        &det,
        &motion,
        &g,
        &InverseResampleOptions::new(Interpolation::Linear, 1.0),
    )?
    .volume;
    let seed = o.seed;
    let noisy = |data: &mut [f32], stream: u64| {
        data.par_iter_mut().enumerate().for_each(|(i, v)| {
            *v += (o.noise * noise::normal(seed ^ stream, i as u64)) as f32;
        });
    };
    let mut exhale = ex;
    exhale
        .data_mut()
        .par_iter_mut()
        .zip(ex_det.data().par_iter())
        .for_each(|(v, &j)| {
            if *v < -500.0 && *v > -990.0 && j > 0.0 {
                *v = (1000.0 + *v) / j - 1000.0;
            }
        });
    let mut inhale = inhale_clean;
    noisy(inhale.data_mut(), 0x1);
    noisy(exhale.data_mut(), 0x2);
    let landmarks_exhale = landmarks.iter().map(|&b| motion.apply(b)).collect();
    let lobes = Volume::new(g, lobes)?;
    let lobe_script = script_of(&anat, &g);
    Ok(LungPhantom {
        inhale,
        exhale,
        lobes,
        motion,
        landmarks_inhale: landmarks,
        landmarks_exhale,
        lobe_script,
    })
}

/// The fissures' end points on the lung boundary every few axial sections.
fn script_of(anat: &Anatomy, g: &Geometry) -> LobeScript {
    let inv = g.index_to_physical_matrix().inverse();
    let mut fissures = Vec::new();
    for (kind, lung) in [
        (FissureKind::RightOblique, 0usize),
        (FissureKind::RightHorizontal, 0),
        (FissureKind::LeftOblique, 1),
    ] {
        let mut keys = Vec::new();
        for k in 0..g.dims[2] {
            let z = g.index_to_physical(DVec3::new(0.0, 0.0, k as f64)).z;
            let y = match kind {
                FissureKind::RightHorizontal => {
                    let yh = anat.horizontal_y(z);
                    if yh >= anat.oblique_y(0, z) {
                        continue;
                    }
                    yh
                }
                _ => anat.oblique_y(lung, z),
            };
            // Lung extent along x on the line (y, z).
            let xs: Vec<f64> = (0..g.dims[0])
                .map(|i| g.index_to_physical(DVec3::new(i as f64, 0.0, 0.0)).x)
                .filter(|&x| anat.lung(DVec3::new(x, y, z)) == Some(lung))
                .collect();
            if xs.len() < 4 {
                continue;
            }
            let (x0, x1) = (xs[0], xs[xs.len() - 1]);
            let a = inv * (DVec3::new(x0, y, z) - g.origin);
            let b = inv * (DVec3::new(x1, y, z) - g.origin);
            keys.push(KeyPoints {
                slice: k,
                from: [a.x, a.y],
                to: [b.x, b.y],
            });
        }
        if keys.is_empty() {
            continue;
        }
        let first = keys[0].slice;
        let last = keys[keys.len() - 1].slice;
        // Every fourth section is a key, plus the last.
        let mut kept: Vec<KeyPoints> = keys.iter().step_by(4).cloned().collect();
        if kept.last().map(|k| k.slice) != Some(last) {
            kept.push(keys[keys.len() - 1].clone());
        }
        fissures.push(FissureScript {
            kind,
            first,
            last,
            keys: kept,
        });
    }
    LobeScript { fissures }
}

/// Options of [`known_deformation`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownDeformationOptions {
    /// Largest control-point displacement, mm.
    pub magnitude: f64,
    /// Control-point spacing, mm.
    pub spacing: f64,
    /// Seed.
    pub seed: u64,
    /// Intensity change (inter-subject-like pair): gain, offset, smooth bias and gamma.
    pub intensity_change: bool,
}

/// A known smooth deformation of `volume` (see the [module docs](self)): the field
/// `fixed → moving` and the moving volume.
///
/// # Errors
/// [`RegisterError::Option`] for a non-positive spacing or a negative magnitude,
/// [`RegisterError::Map`] / [`RegisterError::Warp`] if the lattice or resampling fails.
pub fn known_deformation(
    volume: &Volume<f32>,
    o: &KnownDeformationOptions,
) -> Result<(BSplineLattice, Volume<f32>), RegisterError> {
    let spacing = crate::error::positive("spacing", o.spacing)?;
    let magnitude = crate::error::non_negative("magnitude", o.magnitude)?;
    let g = *volume.geometry();
    let ext = g.spacing
        * DVec3::new(
            (g.dims[0] - 1) as f64,
            (g.dims[1] - 1) as f64,
            (g.dims[2] - 1) as f64,
        );
    let regions: [usize; 3] = std::array::from_fn(|a| ((ext[a] / spacing).round() as usize).max(2));
    let mut lat = crate::dense::lattice_on(&g, regions)?;
    let c = lat.counts();
    let mut rng = Stream::new(o.seed);
    // Interior control points only (three outer layers fixed), bounded so J stays positive:
    // a cubic B-spline displacement with control jumps below spacing/2.5 cannot fold.
    let cap = magnitude.min(0.4 * spacing);
    for k in 3..c[2].saturating_sub(3) {
        for j in 3..c[1].saturating_sub(3) {
            for i in 3..c[0].saturating_sub(3) {
                let d = loop {
                    let v = DVec3::new(
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                    );
                    if v.length_squared() <= 1.0 {
                        break v;
                    }
                };
                lat.move_control_point([i, j, k], d * cap)?;
            }
        }
    }
    let opts = InverseResampleOptions::new(Interpolation::CubicBSpline, 0.0)
        .with_boundary(volmorph_volume::sample::Boundary::Clamp);
    let mut moving: Volume<f32> = pullback_through_inverse(volume, &lat, &g, &opts)?.volume;
    if o.intensity_change {
        let (lo, hi) = crate::metrics::value_range(volume.data(), None);
        let range = (hi - lo).max(1e-6);
        let centre = g.index_to_physical(DVec3::new(
            g.dims[0] as f64 / 2.0,
            g.dims[1] as f64 / 2.0,
            g.dims[2] as f64 / 2.0,
        ));
        let bias_axis = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.5).normalize();
        let len = ext.length();
        moving
            .data_mut()
            .par_iter_mut()
            .enumerate()
            .for_each(|(n, v)| {
                let p = g.voxel_position(n);
                let t = ((f64::from(*v) - lo) / range).clamp(0.0, 1.0);
                let gamma = t.powf(0.8);
                let bias =
                    1.0 + 0.15 * ((p - centre).dot(bias_axis) / len * std::f64::consts::PI).sin();
                *v = (lo + range * (0.05 + 0.9 * gamma) * bias) as f32;
            });
    }
    Ok((lat, moving))
}

/// `det Dφ` of the breathing motion averaged over each lobe of the inhale grid (index = label).
///
/// # Errors
/// [`RegisterError::Warp`] if the Jacobian map cannot be computed.
pub fn true_lobe_volume_change(p: &LungPhantom) -> Result<[f64; 6], RegisterError> {
    let det = volmorph_warp::jacobian::jacobian_determinant(&p.motion, p.lobes.geometry())?;
    let mut sum = [0.0; 6];
    let mut count = [0usize; 6];
    for (&l, &d) in p.lobes.data().iter().zip(det.data()) {
        sum[l as usize] += f64::from(d);
        count[l as usize] += 1;
    }
    Ok(std::array::from_fn(|l| {
        if count[l] > 0 {
            sum[l] / count[l] as f64
        } else {
            f64::NAN
        }
    }))
}
