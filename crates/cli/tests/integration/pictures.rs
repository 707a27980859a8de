//! End-to-end tests of the pictures the tool writes: slices with orientation labels at a
//! readable size, mesh pictures from any view in the mesh's own colours, and animations as
//! single APNG or GIF files.

use crate::common;

use std::path::Path;

use common::{fails, ok};
use glam::{DMat3, DVec3};
use volmorph_render::annotate::LABEL_COLOR;
use volmorph_render::{RgbaImage, read_png};
use volmorph_volume::{AnyVolume, Geometry, Volume};

fn labelled_pixels(img: &RgbaImage) -> usize {
    img.pixels().iter().filter(|p| **p == LABEL_COLOR).count()
}

/// Label pixels in the left and right eighths of the middle rows.
fn edge_pixels(img: &RgbaImage) -> (usize, usize) {
    let (w, h) = (img.width(), img.height());
    let count = |x0: u32, x1: u32| {
        (h / 2 - h / 8..h / 2 + h / 8)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get(x, y) == Some(LABEL_COLOR))
            .count()
    };
    (count(0, w / 8), count(w - w / 8, w))
}

fn write_volume(path: &Path, direction: DMat3, spacing: DVec3) {
    let g = Geometry::new([30, 20, 10])
        .with_spacing(spacing)
        .with_direction(direction);
    let v = Volume::<f32>::from_fn(g, |i, j, k| (i + j + k) as f32).unwrap();
    volmorph_volume_io::write(path, &AnyVolume::from(v)).unwrap();
}

#[test]
fn slice_labels_follow_the_direction_matrix_and_the_size_the_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = d.join("plain.nii.gz");
    let flipped = d.join("flipped.nii.gz");
    let spacing = DVec3::new(0.5, 1.5, 3.0);
    write_volume(&plain, DMat3::IDENTITY, spacing);
    write_volume(
        &flipped,
        DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
        spacing,
    );
    let a = d.join("a.png");
    let b = d.join("b.png");
    ok(&[&"slice", &plain, &"-o", &a, &"--axis", &"z"]);
    ok(&[&"slice", &flipped, &"-o", &b, &"--axis", &"z"]);
    let (a, b) = (read_png(&a).unwrap(), read_png(&b).unwrap());
    // 30 × 0.5 mm by 20 × 1.5 mm: 15 × 30 mm, the longer side enlarged to 512 pixels.
    assert_eq!((a.width(), a.height()), (256, 512));
    // R on the left and L on the right of the identity picture, swapped when i is flipped.
    let (al, ar) = edge_pixels(&a);
    let (bl, br) = edge_pixels(&b);
    assert!(al > 0 && ar > 0 && al != ar, "{al} {ar}");
    assert_eq!((bl, br), (ar, al));
    // --no-labels draws none; --zoom 1 and --size override the size.
    let c = d.join("c.png");
    ok(&[
        &"slice",
        &plain,
        &"-o",
        &c,
        &"--axis",
        &"y",
        &"--no-labels",
        &"--zoom",
        &"1",
    ]);
    let c = read_png(&c).unwrap();
    assert_eq!(labelled_pixels(&c), 0);
    // 30 × 0.5 mm by 10 × 3 mm at one pixel per 0.5 mm.
    assert_eq!((c.width(), c.height()), (30, 60));
    let e = d.join("e.png");
    ok(&[
        &"slice",
        &plain,
        &"-o",
        &e,
        &"--axis",
        &"x",
        &"--size",
        &"300",
        &"--voxel-aspect",
        &"--interpolation",
        &"nearest",
    ]);
    let img = read_png(&e).unwrap();
    assert_eq!((img.width(), img.height()), (300, 150));
    let err = fails(&[&"slice", &plain, &"-o", &e, &"--zoom", &"0"]);
    assert!(err.contains("zoom"), "{err}");
}

/// A red-vertex triangle pair as ASCII PLY.
const RED_SQUARE: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
    property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n\
    property uchar blue\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
    0 0 0 220 10 10\n1 0 0 220 10 10\n1 1 0 220 10 10\n0 1 0 220 10 10\n3 0 1 2\n3 0 2 3\n";

/// Mean colour of the pixels that are not the white background.
fn mean_foreground(img: &RgbaImage) -> [f64; 3] {
    let fg: Vec<_> = img
        .pixels()
        .iter()
        .filter(|p| p[..3] != [255, 255, 255])
        .collect();
    assert!(!fg.is_empty(), "nothing drawn");
    let n = fg.len() as f64;
    [0, 1, 2].map(|k| fg.iter().map(|p| f64::from(p[k])).sum::<f64>() / n)
}

#[test]
fn mesh_render_draws_the_file_colours_from_any_view() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ply = d.join("red.ply");
    std::fs::write(&ply, RED_SQUARE).unwrap();
    let png = d.join("red.png");
    // From above (z up, elevation 60°) and from below: both sides show the colour.
    for view in ["30,60", "30,-60", "top", "iso"] {
        ok(&[
            &"mesh", &"render", &ply, &"-o", &png, &"--view", &view, &"--size", &"64x48",
        ]);
        let [r, g, b] = mean_foreground(&read_png(&png).unwrap());
        assert!(r > 2.0 * g && r > 2.0 * b, "{view}: {r} {g} {b}");
    }
    ok(&[
        &"mesh",
        &"render",
        &ply,
        &"-o",
        &png,
        &"--no-colors",
        &"--size",
        &"64x48",
    ]);
    let [r, g, b] = mean_foreground(&read_png(&png).unwrap());
    assert!(g > 0.5 * r && b > 0.3 * r, "clay, not red: {r} {g} {b}");

    // --up y against --up z: the same presets as `frep render`, so the pictures differ for a
    // shape that is not symmetric about the two axes.
    let teapot = d.join("teapot.ply");
    let vol = d.join("teapot.nii");
    ok(&[&"phantom", &"teapot", &"-o", &vol, &"--size", &"32"]);
    ok(&[&"isosurface", &vol, &"--level", &"127", &"-o", &teapot]);
    let (yz, yy) = (d.join("z.png"), d.join("y.png"));
    for (up, out) in [("z", &yz), ("y", &yy)] {
        ok(&[
            &"mesh", &"render", &teapot, &"-o", out, &"--view", &"30,20", &"--up", &up, &"--size",
            &"80x60",
        ]);
    }
    assert_ne!(read_png(&yz).unwrap(), read_png(&yy).unwrap());
    for bad in ["30", "north", "30,abc"] {
        let err = fails(&[&"mesh", &"render", &teapot, &"-o", &yz, &"--view", &bad]);
        assert!(err.contains("--view"), "{bad}: {err}");
    }
}

#[test]
fn nurbs_slice_colours_reach_the_mesh_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = d.join("sdf.nii");
    ok(&[
        &"phantom", &"sphere", &"-o", &src, &"--kind", &"sdf", &"--size", &"14",
    ]);
    let model = d.join("m.json");
    ok(&[&"nurbs", &"fit", &src, &"-o", &model, &"--name", &"d"]);
    let info: serde_json::Value = serde_json::from_str(&ok(&[&"info", &"--json", &src])).unwrap();
    let cz = info["origin"][2].as_f64().unwrap() + info["spacing"][2].as_f64().unwrap() * 6.5;
    let plane = format!("0,0,1,{}", -cz);
    for per_polygon in [false, true] {
        let cut = d.join(format!("cut{per_polygon}.ply"));
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"nurbs",
            &"slice",
            &model,
            &"--plane",
            &plane,
            &"--attribute",
            &"d",
            &"-o",
            &cut,
            &"--colormap",
            &"hot",
        ];
        if per_polygon {
            args.push(&"--per-polygon");
        }
        ok(&args);
        let png = d.join("cut.png");
        ok(&[
            &"mesh", &"render", &cut, &"-o", &png, &"--view", &"top", &"--size", &"64x64",
        ]);
        let img = read_png(&png).unwrap();
        // The hot map runs black–red–yellow–white: red dominates blue everywhere, and the
        // picture has dark (negative distance, inside) and bright parts.
        let [r, _, b] = mean_foreground(&img);
        assert!(r > 1.5 * b, "per polygon {per_polygon}: {r} {b}");
        let lum: Vec<u32> = img
            .pixels()
            .iter()
            .filter(|p| p[..3] != [255, 255, 255])
            .map(|p| u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]))
            .collect();
        let (lo, hi) = (lum.iter().min().unwrap(), lum.iter().max().unwrap());
        assert!(hi - lo > 200, "per polygon {per_polygon}: {lo}..{hi}");
    }
}

const BLOCK: &str = "model(x[3], a[1])
{
  array corner[3];
  corner = [-1, -1, -1];
  model = hfBlock(x, corner, 2, 2, 2);
}
";

const BALL: &str = "model(x[3], a[1])
{
  t0 = sqrt(x[1]*x[1] + x[2]*x[2] + x[3]*x[3]);
  model = 1.1 - t0;
}
";

/// The frames of a GIF, decoded to RGBA.
fn gif_frames(path: &Path) -> Vec<Vec<u8>> {
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut dec = opts.read_info(std::fs::File::open(path).unwrap()).unwrap();
    let mut out = Vec::new();
    while let Some(f) = dec.read_next_frame().unwrap() {
        out.push(f.buffer.to_vec());
    }
    out
}

/// Frame count of an APNG's `acTL` chunk and the number of frame data chunks after the first.
fn apng_frames(path: &Path) -> (u32, usize) {
    let bytes = std::fs::read(path).unwrap();
    let at = bytes
        .windows(4)
        .position(|w| w == b"acTL")
        .expect("animated PNG");
    let n = u32::from_be_bytes(bytes[at + 4..at + 8].try_into().unwrap());
    let fdat = bytes.windows(4).filter(|w| *w == b"fdAT").count();
    (n, fdat)
}

#[test]
fn frep_morph_and_turntables_write_animation_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (block, ball) = (d.join("block.hf"), d.join("ball.hf"));
    std::fs::write(&block, BLOCK).unwrap();
    std::fs::write(&ball, BALL).unwrap();
    let gif = d.join("morph.gif");
    let out = ok(&[
        &"frep",
        &"morph",
        &block,
        &ball,
        &"--frames",
        &"4",
        &"--size",
        &"32",
        &"-o",
        &gif,
    ]);
    assert!(out.contains("4 frames") && out.contains("GIF"), "{out}");
    let frames = gif_frames(&gif);
    assert_eq!(frames.len(), 4);
    assert_eq!(frames[0].len(), 32 * 32 * 4);
    assert_ne!(frames[0], frames[3], "the shape changes");
    let apng = d.join("morph.png");
    ok(&[
        &"frep",
        &"morph",
        &block,
        &ball,
        &"--frames",
        &"3",
        &"--size",
        &"24",
        &"-o",
        &apng,
        &"--delay",
        &"50",
    ]);
    assert_eq!(apng_frames(&apng), (3, 2));
    // The first frame (what plain PNG readers show) is the block, the folder output's frame 0.
    let folder = d.join("frames");
    ok(&[
        &"frep",
        &"morph",
        &block,
        &ball,
        &"--frames",
        &"3",
        &"--size",
        &"24",
        &"-o",
        &folder,
    ]);
    assert_eq!(
        read_png(&apng).unwrap(),
        read_png(&folder.join("frame0000.png")).unwrap()
    );
    let err = fails(&[
        &"frep",
        &"morph",
        &block,
        &ball,
        &"-o",
        &d.join("morph.mp4"),
    ]);
    assert!(err.contains("morph.mp4") && err.contains(".gif"), "{err}");
    assert!(!d.join("morph.mp4").exists());

    // A volume turntable as one GIF.
    let vol = d.join("t.nii");
    ok(&[&"phantom", &"teapot", &"-o", &vol, &"--size", &"24"]);
    let spin = d.join("spin.gif");
    ok(&[
        &"render",
        &vol,
        &"-o",
        &spin,
        &"--frames",
        &"3",
        &"--size",
        &"24",
        &"--mode",
        &"mip",
    ]);
    let frames = gif_frames(&spin);
    assert_eq!(frames.len(), 3);
    assert_ne!(frames[0], frames[1], "the view turns");
}
