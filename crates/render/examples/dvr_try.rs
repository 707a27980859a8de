//! Scratch timing of direct volume rendering (development aid).
use std::time::Instant;
use volmorph_render::*;
fn cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let f: Vec<&str> = s.rsplit(')').next().unwrap().split_whitespace().collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0
}
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let vol = volmorph_volume::format::read(std::path::Path::new(&path)).unwrap();
    let dv = DvrVolume::new(&vol).unwrap();
    let tf = TransferPreset::CtBone.build((0.0, 1.0)).unwrap();
    let mut opts = DvrOptions::new(tf);
    opts.step = Some(0.5);
    let r = DvrRenderer::new(&dv, opts).unwrap();
    let size: u32 = std::env::var("SIZE")
        .map(|v| v.parse().unwrap())
        .unwrap_or(512);
    let g = dv.geometry();
    let b = g.physical_bounds();
    let cam = Orbit::named("anterior", UpAxis::Z)
        .unwrap()
        .camera(
            b,
            Projection::Perspective {
                fov_y: DEFAULT_FOV_Y,
            },
            Framing::Sphere,
            size,
            size,
        )
        .unwrap();
    let n: usize = std::env::var("N").map(|v| v.parse().unwrap()).unwrap_or(5);
    // 200 handles: sources on a jittered lattice inside the box, targets moved smoothly.
    let (lo, hi) = b;
    let mut src = Vec::new();
    let mut s = 12345u64;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..200 {
        src.push(glam::DVec3::new(
            lo.x + rnd() * (hi.x - lo.x),
            lo.y + rnd() * (hi.y - lo.y),
            lo.z + rnd() * (hi.z - lo.z),
        ));
    }
    let c = 0.5 * (lo + hi);
    let dst: Vec<glam::DVec3> = src
        .iter()
        .map(|p| {
            let q = *p - c;
            *p + glam::DVec3::new(6.0 * (q.z / 40.0).sin(), 4.0 * (q.x / 50.0).cos(), 0.0)
        })
        .collect();
    let t = Instant::now();
    let map = volmorph_deform::AffineMls::new(
        &dst,
        &src,
        volmorph_deform::Weighting::InverseDistance { alpha: 1.0 },
    )
    .unwrap();
    let view = DeformedView::from_map(&dv, &map, [33, 33, 33]).unwrap();
    println!("mls grid {:?}", t.elapsed());
    for _ in 0..n {
        let t = Instant::now();
        let c0 = cpu();
        let img = r.render(&cam).unwrap();
        println!("render {:?} cpu {:.3}", t.elapsed(), cpu() - c0);
        let t = Instant::now();
        let c0 = cpu();
        let img2 = r.render_deformed(&view, &cam).unwrap();
        println!("deformed {:?} cpu {:.3}", t.elapsed(), cpu() - c0);
        write_png_rgba(std::path::Path::new("/tmp/pic/dvr.png"), &img).unwrap();
        write_png_rgba(std::path::Path::new("/tmp/pic/dvr_def.png"), &img2).unwrap();
    }
}
