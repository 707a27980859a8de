//! Text on pictures: a built-in 5 × 7 bitmap font and the patient-orientation labels
//! (R/L, A/P, S/I) that slice viewers print at the edges of a slice.
//!
//! # Why a built-in font
//!
//! The pictures need fewer than twenty glyphs — the six orientation letters `R L A P S I`, the
//! digits, `-`, `.` and the space — drawn at integer magnifications with a dark outline so
//! they read on any grey level or colour map. A bitmap of 5 × 7 pixels per glyph is exact at
//! every integer scale, needs no rasteriser, anti-aliasing or font file, and adds no
//! dependency; a font crate (TrueType parsing and rasterising) would bring all of that for a
//! dozen characters.
//!
//! # Orientation letters
//!
//! volmorph's physical space is **LPS** (DESIGN.md): +x points to the patient's **L**eft, +y to
//! **P**osterior, +z to **S**uperior; the opposite directions are **R**ight, **A**nterior and
//! **I**nferior. The label at a picture edge names the physical direction the picture runs in
//! towards that edge ([`direction_label`]): the right edge gets the letter of the column
//! direction, the top edge the letter of the row direction pointing up.
//!
//! For an oblique direction the label has **two letters**, dominant first (as 3D Slicer and
//! DICOM viewers do), when the second-largest direction cosine is at least
//! [`SECOND_LETTER_MIN_COSINE`]; otherwise only the dominant letter is shown.

use glam::{DMat3, DVec3};
use volmorph_volume::slice::Axis;

use crate::RgbaImage;
use crate::error::RenderError;

/// Width of a glyph cell in font pixels (before magnification).
pub const GLYPH_WIDTH: u32 = 5;
/// Height of a glyph cell in font pixels (before magnification).
pub const GLYPH_HEIGHT: u32 = 7;
/// Font pixels between two glyphs of a text.
pub const GLYPH_SPACING: u32 = 1;

/// Smallest direction cosine (absolute value) for which an oblique direction gets a second
/// letter: 0.25, the cosine of about 75.5°, i.e. a direction tilted more than about 14.5° from
/// its dominant axis towards another. Below it the picture reads as the dominant plane and one
/// letter is clearer. A design choice (viewers differ); stated here so the labels can be
/// predicted.
pub const SECOND_LETTER_MIN_COSINE: f64 = 0.25;

/// Colour of label text (opaque yellow, as slice viewers draw annotations).
pub const LABEL_COLOR: [u8; 4] = [255, 255, 0, 255];
/// Colour of the outline drawn around label text so it reads on light backgrounds.
pub const OUTLINE_COLOR: [u8; 4] = [0, 0, 0, 255];

/// Shorter picture side, in pixels, below which [`draw_orientation_labels`] draws nothing: a
/// smaller picture has no room for four labels without hiding the slice.
pub const LABEL_MIN_SIDE: u32 = 48;

/// The 5 × 7 bitmap of `c` (rows top to bottom, bit 4 = leftmost pixel), or `None` for a
/// character the font does not have.
#[must_use]
pub fn glyph(c: char) -> Option<[u8; 7]> {
    Some(match c {
        'R' => [
            0b11110, 0b10001, 0b10001, 0b11110, 0b10100, 0b10010, 0b10001,
        ],
        'L' => [
            0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111,
        ],
        'A' => [
            0b01110, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001,
        ],
        'P' => [
            0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000,
        ],
        'S' => [
            0b01111, 0b10000, 0b10000, 0b01110, 0b00001, 0b00001, 0b11110,
        ],
        'I' => [
            0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110,
        ],
        '0' => [
            0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110,
        ],
        '1' => [
            0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110,
        ],
        '2' => [
            0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111,
        ],
        '3' => [
            0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110,
        ],
        '4' => [
            0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010,
        ],
        '5' => [
            0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110,
        ],
        '6' => [
            0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110,
        ],
        '7' => [
            0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000,
        ],
        '8' => [
            0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110,
        ],
        '9' => [
            0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100,
        ],
        '-' => [0, 0, 0, 0b11111, 0, 0, 0],
        '.' => [0, 0, 0, 0, 0, 0b01100, 0b01100],
        ' ' => [0; 7],
        _ => return None,
    })
}

/// Size in picture pixels `(width, height)` of `text` drawn at magnification `scale`
/// (without the outline, which adds `scale` pixels on every side).
#[must_use]
pub fn text_size(text: &str, scale: u32) -> (u32, u32) {
    let n = text.chars().count() as u32;
    let w = if n == 0 {
        0
    } else {
        n * GLYPH_WIDTH + (n - 1) * GLYPH_SPACING
    };
    (w * scale, GLYPH_HEIGHT * scale)
}

/// Draw `text` with its top-left corner at picture pixel `(x, y)` (may be negative or partly
/// outside: pixels outside the picture are dropped), each font pixel a `scale × scale` block
/// of `color`, surrounded by a `scale`-pixel outline of `outline` when given.
///
/// # Errors
/// [`RenderError::InvalidArgument`] for `scale` 0 or a character the font lacks (see
/// [`glyph`]); nothing is drawn then.
pub fn draw_text(
    img: &mut RgbaImage,
    (x, y): (i64, i64),
    text: &str,
    scale: u32,
    color: [u8; 4],
    outline: Option<[u8; 4]>,
) -> Result<(), RenderError> {
    if scale == 0 {
        return Err(RenderError::invalid(
            "text magnification must be at least 1",
        ));
    }
    let glyphs: Vec<[u8; 7]> = text
        .chars()
        .map(|c| {
            glyph(c).ok_or_else(|| {
                RenderError::invalid(format!("the built-in font has no glyph for {c:?}"))
            })
        })
        .collect::<Result<_, _>>()?;
    let s = i64::from(scale);
    // Font pixels that are set, as picture coordinates of their blocks' top-left corners.
    let blocks: Vec<(i64, i64)> = glyphs
        .iter()
        .enumerate()
        .flat_map(|(k, rows)| {
            let gx = x + k as i64 * i64::from(GLYPH_WIDTH + GLYPH_SPACING) * s;
            rows.iter().enumerate().flat_map(move |(r, bits)| {
                (0..GLYPH_WIDTH).filter_map(move |c| {
                    ((bits >> (GLYPH_WIDTH - 1 - c)) & 1 == 1)
                        .then_some((gx + i64::from(c) * s, y + r as i64 * s))
                })
            })
        })
        .collect();
    let mut fill = |x0: i64, y0: i64, side: i64, p: [u8; 4]| {
        for yy in y0.max(0)..(y0 + side).min(i64::from(img.height())) {
            for xx in x0.max(0)..(x0 + side).min(i64::from(img.width())) {
                img.put(xx as u32, yy as u32, p);
            }
        }
    };
    if let Some(o) = outline {
        for &(bx, by) in &blocks {
            fill(bx - s, by - s, 3 * s, o);
        }
    }
    for &(bx, by) in &blocks {
        fill(bx, by, s, color);
    }
    Ok(())
}

/// The orientation letter (LPS) of the component `axis` (0 = x, 1 = y, 2 = z) of `d`, by its
/// sign.
fn axis_letter(d: DVec3, axis: usize) -> char {
    let positive = d[axis] > 0.0;
    match (axis, positive) {
        (0, true) => 'L',
        (0, false) => 'R',
        (1, true) => 'P',
        (1, false) => 'A',
        (2, true) => 'S',
        _ => 'I',
    }
}

/// The letters of an edge label: one or two of `R L A P S I`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdgeLabel {
    letters: [char; 2],
    count: u8,
}

impl EdgeLabel {
    /// The label as a string (`"R"`, `"LA"`, …).
    #[must_use]
    pub fn as_string(&self) -> String {
        self.letters[..usize::from(self.count)].iter().collect()
    }
}

impl std::fmt::Display for EdgeLabel {
    /// The letters, dominant first.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.as_string())
    }
}

/// The label of the physical direction `d` (LPS, need not be unit length): the letter of its
/// largest component, followed by the letter of the second-largest when that component's
/// direction cosine is at least [`SECOND_LETTER_MIN_COSINE`].
///
/// ```
/// use glam::DVec3;
/// use volmorph_render::annotate::direction_label;
/// assert_eq!(direction_label(DVec3::X).unwrap().to_string(), "L");
/// assert_eq!(direction_label(-DVec3::Y).unwrap().to_string(), "A");
/// // 30° from −x towards +z: right and a little superior.
/// let d = DVec3::new(-(30f64.to_radians().cos()), 0.0, 30f64.to_radians().sin());
/// assert_eq!(direction_label(d).unwrap().to_string(), "RS");
/// ```
///
/// # Errors
/// [`RenderError::InvalidArgument`] when `d` is zero or not finite.
pub fn direction_label(d: DVec3) -> Result<EdgeLabel, RenderError> {
    let len = d.length();
    if !(len > 0.0 && len.is_finite()) {
        return Err(RenderError::invalid(format!(
            "direction {d} has no orientation (zero or not finite)"
        )));
    }
    let u = d / len;
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| u[b].abs().total_cmp(&u[a].abs()));
    let first = axis_letter(u, order[0]);
    let second = axis_letter(u, order[1]);
    let two = u[order[1]].abs() >= SECOND_LETTER_MIN_COSINE;
    Ok(EdgeLabel {
        letters: [first, second],
        count: if two { 2 } else { 1 },
    })
}

/// The labels of the four edges of a slice picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrientationLabels {
    /// Left edge: the direction of decreasing column index.
    pub left: EdgeLabel,
    /// Right edge: the direction of increasing column index.
    pub right: EdgeLabel,
    /// Top edge: the direction of increasing second index (pictures show it pointing up).
    pub top: EdgeLabel,
    /// Bottom edge: the direction of decreasing second index.
    pub bottom: EdgeLabel,
}

impl OrientationLabels {
    /// The labels of a slice perpendicular to `axis` of a volume whose direction matrix (columns
    /// = physical directions of the i, j, k axes, LPS) is `direction`, laid out as
    /// [`volmorph_volume::slice`] lays pictures out: columns along the first in-plane axis
    /// (left to right), rows along the second with its highest index at the top.
    ///
    /// For an identity direction an axial (`Z`) slice is labelled R left, L right, P top and
    /// A bottom.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when an in-plane direction column is zero or not finite.
    pub fn for_slice(direction: DMat3, axis: Axis) -> Result<Self, RenderError> {
        let [first, second] = axis.in_plane();
        let (c, r) = (direction.col(first), direction.col(second));
        Ok(Self {
            left: direction_label(-c)?,
            right: direction_label(c)?,
            top: direction_label(r)?,
            bottom: direction_label(-r)?,
        })
    }
}

/// Magnification of label text on a `width × height` picture: one font pixel per 128 pixels
/// of the shorter side (5 × 7-pixel letters up to 255 pixels, 20 × 28 at 512), at least 1.
#[must_use]
pub fn label_scale(width: u32, height: u32) -> u32 {
    (width.min(height) / 128).max(1)
}

/// Draw `labels` at the middle of each edge of `img`, [`LABEL_COLOR`] outlined in
/// [`OUTLINE_COLOR`], [`label_scale`] pixels per font pixel and as far from the edge. Pictures
/// whose shorter side is below [`LABEL_MIN_SIDE`] are left unchanged.
///
/// # Errors
/// None in practice (the labels use only glyphs of the font); the `Result` is that of
/// [`draw_text`].
pub fn draw_orientation_labels(
    img: &mut RgbaImage,
    labels: &OrientationLabels,
) -> Result<(), RenderError> {
    let (w, h) = (img.width(), img.height());
    if w.min(h) < LABEL_MIN_SIDE {
        return Ok(());
    }
    let s = label_scale(w, h);
    let margin = i64::from(2 * s);
    let (w, h) = (i64::from(w), i64::from(h));
    let place = [
        (labels.left, Edge::Left),
        (labels.right, Edge::Right),
        (labels.top, Edge::Top),
        (labels.bottom, Edge::Bottom),
    ];
    for (label, edge) in place {
        let text = label.as_string();
        let (tw, th) = text_size(&text, s);
        let (tw, th) = (i64::from(tw), i64::from(th));
        let at = match edge {
            Edge::Left => (margin, (h - th) / 2),
            Edge::Right => (w - margin - tw, (h - th) / 2),
            Edge::Top => ((w - tw) / 2, margin),
            Edge::Bottom => ((w - tw) / 2, h - margin - th),
        };
        draw_text(img, at, &text, s, LABEL_COLOR, Some(OUTLINE_COLOR))?;
    }
    Ok(())
}

#[derive(Clone, Copy)]
enum Edge {
    Left,
    Right,
    Top,
    Bottom,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn label(d: DVec3) -> String {
        direction_label(d).unwrap().to_string()
    }

    #[test]
    fn lps_letters() {
        assert_eq!(label(DVec3::X), "L");
        assert_eq!(label(-DVec3::X), "R");
        assert_eq!(label(DVec3::Y), "P");
        assert_eq!(label(-DVec3::Y), "A");
        assert_eq!(label(DVec3::Z), "S");
        assert_eq!(label(-DVec3::Z), "I");
        // Length does not matter.
        assert_eq!(label(DVec3::new(0.0, 0.0, -7.5)), "I");
        assert!(direction_label(DVec3::ZERO).is_err());
        assert!(direction_label(DVec3::new(f64::NAN, 0.0, 1.0)).is_err());
    }

    #[test]
    fn oblique_directions_get_a_second_letter_past_the_threshold() {
        let tilt = |deg: f64| {
            let t = deg.to_radians();
            DVec3::new(t.cos(), -t.sin(), 0.0)
        };
        assert_eq!(label(tilt(5.0)), "L");
        assert_eq!(label(tilt(10.0)), "L");
        assert_eq!(label(tilt(20.0)), "LA");
        assert_eq!(label(tilt(70.0)), "AL");
        // Exactly at the threshold the second letter is shown.
        let c = SECOND_LETTER_MIN_COSINE;
        assert_eq!(label(DVec3::new(0.0, (1.0 - c * c).sqrt(), c)), "PS");
    }

    #[test]
    fn identity_axial_coronal_sagittal() {
        let s = |axis| {
            let l = OrientationLabels::for_slice(DMat3::IDENTITY, axis).unwrap();
            format!("{} {} {} {}", l.left, l.right, l.top, l.bottom)
        };
        assert_eq!(s(Axis::Z), "R L P A");
        assert_eq!(s(Axis::Y), "R L S I");
        assert_eq!(s(Axis::X), "A P S I");
    }

    #[test]
    fn text_pixels_match_the_glyphs() {
        let mut img = RgbaImage::new(40, 20, [0, 0, 0, 255]).unwrap();
        draw_text(&mut img, (1, 2), "10", 2, LABEL_COLOR, None).unwrap();
        // '1' top row 00100: font pixel (2, 0) is set, (0, 0) is not.
        assert_eq!(img.get(1 + 2 * 2, 2), Some(LABEL_COLOR));
        assert_eq!(img.get(1, 2), Some([0, 0, 0, 255]));
        // '0' starts 12 pixels to the right (6 font pixels × 2); its row 3 is 10101.
        let x0 = 1 + 12;
        assert_eq!(img.get(x0 + 2 * 2, 2 + 3 * 2), Some(LABEL_COLOR));
        assert_eq!(img.get(x0 + 2, 2 + 3 * 2), Some([0, 0, 0, 255]));
        let set = img.pixels().iter().filter(|p| **p == LABEL_COLOR).count();
        let bits: u32 = ['1', '0']
            .iter()
            .map(|&c| {
                glyph(c)
                    .unwrap()
                    .iter()
                    .map(|b| b.count_ones())
                    .sum::<u32>()
            })
            .sum();
        assert_eq!(set as u32, bits * 4);
        assert_eq!(text_size("10", 2), (22, 14));
        // Unknown characters and zero scale are errors; drawing off the picture is clipped.
        assert!(draw_text(&mut img, (0, 0), "Q", 1, LABEL_COLOR, None).is_err());
        assert!(draw_text(&mut img, (0, 0), "1", 0, LABEL_COLOR, None).is_err());
        draw_text(
            &mut img,
            (-100, -100),
            "-.",
            3,
            LABEL_COLOR,
            Some(OUTLINE_COLOR),
        )
        .unwrap();
        draw_text(&mut img, (35, 15), "8", 3, LABEL_COLOR, Some(OUTLINE_COLOR)).unwrap();
    }

    #[test]
    fn every_font_character_has_a_distinct_glyph() {
        let chars: Vec<char> = "RLAPSI0123456789-.".chars().collect();
        for (i, a) in chars.iter().enumerate() {
            let ga = glyph(*a).unwrap();
            assert!(ga.iter().all(|r| *r < 32), "{a} is 5 pixels wide");
            for b in &chars[i + 1..] {
                assert_ne!(ga, glyph(*b).unwrap(), "{a} and {b}");
            }
        }
    }
}
