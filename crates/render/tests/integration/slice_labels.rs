//! Orientation labels and picture size of slice pictures taken from volumes with identity,
//! flipped and permuted direction matrices and anisotropic spacing.

use glam::{DMat3, DVec3};
use volmorph_render::annotate::{LABEL_COLOR, draw_orientation_labels};
use volmorph_render::{
    OrientationLabels, RgbaImage, SliceStyle, Window, render_slice, slice_picture_size,
};
use volmorph_volume::slice::{self, Axis, SlicePosition};
use volmorph_volume::{AnyVolume, Geometry, Volume};

fn volume(dims: [usize; 3], spacing: DVec3, direction: DMat3) -> AnyVolume {
    let g = Geometry::new(dims)
        .with_spacing(spacing)
        .with_direction(direction);
    // A smooth ramp, so the picture is not uniform.
    AnyVolume::from(Volume::<f32>::from_fn(g, |i, j, k| (i + 2 * j + 3 * k) as f32).unwrap())
}

fn labels_of(vol: &AnyVolume, axis: Axis) -> (OrientationLabels, String) {
    let l = OrientationLabels::for_slice(vol.geometry().direction, axis).unwrap();
    let s = format!("{} {} {} {}", l.left, l.right, l.top, l.bottom);
    (l, s)
}

/// The picture of the middle slice along `axis` with labels, and the label pixels alone.
fn picture(vol: &AnyVolume, axis: Axis) -> (RgbaImage, OrientationLabels) {
    let n = vol.geometry().dims[axis.index()];
    let s = slice::extract(vol, axis, SlicePosition::Index((n / 2) as f64)).unwrap();
    let (labels, _) = labels_of(vol, axis);
    let style = SliceStyle {
        // Everything mid-grey-to-white: no pixel of the slice itself is yellow.
        window: Some(Window::from_range(-1e6, 1e6).unwrap()),
        labels: Some(labels),
        ..SliceStyle::default()
    };
    (render_slice(&s, &style).unwrap(), labels)
}

fn label_mask(img: &RgbaImage) -> Vec<bool> {
    img.pixels().iter().map(|p| *p == LABEL_COLOR).collect()
}

/// The label pixels of `img` are exactly those of `labels` drawn on a blank picture of its
/// size: every glyph is where it should be, and no other.
fn assert_labels_drawn(img: &RgbaImage, labels: &OrientationLabels) {
    let mut blank = RgbaImage::new(img.width(), img.height(), [0, 0, 0, 255]).unwrap();
    draw_orientation_labels(&mut blank, labels).unwrap();
    assert_eq!(label_mask(img), label_mask(&blank));
}

/// Count of label pixels in the `(x0..x1, y0..y1)` box.
fn count(img: &RgbaImage, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
    (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get(x, y) == Some(LABEL_COLOR))
        .count()
}

#[test]
fn identity_flipped_and_permuted_directions_label_the_edges_accordingly() {
    let dims = [40, 40, 40];
    let iso = DVec3::ONE;
    let identity = volume(dims, iso, DMat3::IDENTITY);
    assert_eq!(labels_of(&identity, Axis::Z).1, "R L P A");
    assert_eq!(labels_of(&identity, Axis::Y).1, "R L S I");
    assert_eq!(labels_of(&identity, Axis::X).1, "A P S I");

    // i runs towards −x (right) and j towards −y (anterior): as RAS-stored NIfTI in LPS.
    let flipped = volume(dims, iso, DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)));
    assert_eq!(labels_of(&flipped, Axis::Z).1, "L R A P");
    assert_eq!(labels_of(&flipped, Axis::X).1, "P A S I");

    // Permuted: i along +y, j along +z, k along +x (a sagittal acquisition).
    let permuted = volume(dims, iso, DMat3::from_cols(DVec3::Y, DVec3::Z, DVec3::X));
    assert_eq!(labels_of(&permuted, Axis::Z).1, "A P S I");
    assert_eq!(labels_of(&permuted, Axis::Y).1, "A P L R");

    // Oblique: i and j turned 30° about z.
    let t = 30f64.to_radians();
    let oblique = volume(
        dims,
        iso,
        DMat3::from_cols(
            DVec3::new(t.cos(), t.sin(), 0.0),
            DVec3::new(-t.sin(), t.cos(), 0.0),
            DVec3::Z,
        ),
    );
    assert_eq!(labels_of(&oblique, Axis::Z).1, "RA LP PR AL");

    for (vol, axis) in [
        (&identity, Axis::Z),
        (&flipped, Axis::Z),
        (&permuted, Axis::Y),
        (&oblique, Axis::Z),
    ] {
        let (img, labels) = picture(vol, axis);
        assert_labels_drawn(&img, &labels);
    }

    // The glyphs differ between the identity and the flipped volume: the left edge of the
    // identity picture shows R, the flipped one L (fewer pixels: L is a thinner letter).
    let (a, _) = picture(&identity, Axis::Z);
    let (b, _) = picture(&flipped, Axis::Z);
    let (w, h) = (a.width(), a.height());
    let left = (0, w / 8);
    let middle = (h / 2 - h / 8, h / 2 + h / 8);
    let r_pixels = count(&a, left, middle);
    let l_pixels = count(&b, left, middle);
    assert!(r_pixels > 0 && l_pixels > 0);
    assert_ne!(r_pixels, l_pixels);
    // The right edges swap the same letters.
    let right = (w - w / 8, w);
    assert_eq!(count(&a, right, middle), l_pixels);
    assert_eq!(count(&b, right, middle), r_pixels);
}

#[test]
fn anisotropic_spacing_gives_the_physical_aspect_by_default() {
    // 60 × 30 × 12 voxels of 0.8 × 1.1 × 3.5 mm.
    let spacing = DVec3::new(0.8, 1.1, 3.5);
    let dims = [60, 30, 12];
    let vol = volume(dims, spacing, DMat3::IDENTITY);
    for axis in Axis::ALL {
        let [a, b] = axis.in_plane();
        let (img, _) = picture(&vol, axis);
        let (w, h) = (f64::from(img.width()), f64::from(img.height()));
        let physical = (dims[a] as f64 * spacing[a]) / (dims[b] as f64 * spacing[b]);
        assert!(
            (w / h - physical).abs() <= 0.5 / h + 0.5 / w + 1e-12,
            "{axis}: {w}×{h} vs physical ratio {physical}"
        );
        assert_eq!(img.width().max(img.height()), 512, "{axis}");
        let s = slice::extract(&vol, axis, SlicePosition::Index(0.0)).unwrap();
        assert_eq!(
            slice_picture_size(&s, Default::default(), Default::default()).unwrap(),
            (img.width(), img.height())
        );
    }
}
