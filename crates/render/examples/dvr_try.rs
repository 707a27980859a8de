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
    let t = Instant::now();
    let dv = DvrVolume::new(&vol).unwrap();
    println!("prepare {:?}", t.elapsed());
    let tf = TransferPreset::CtBone.build((0.0, 1.0)).unwrap();
    let mut opts = DvrOptions::new(tf);
    opts.step = Some(0.5);
    if std::env::var("NOSHADE").is_ok() {
        opts.shading = None;
    }
    if std::env::var("NOSKIP").is_ok() {
        opts.skip_empty_space = false;
    }
    let t = Instant::now();
    let c0 = cpu();
    let r = DvrRenderer::new(&dv, opts).unwrap();
    println!("renderer {:?} cpu {:.3}", t.elapsed(), cpu() - c0);
    println!("visible bricks {:?}", r.visible_bricks());
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
    for _ in 0..n {
        let t = Instant::now();
        let c0 = cpu();
        let img = r.render(&cam).unwrap();
        println!("render {:?} cpu {:.3}", t.elapsed(), cpu() - c0);

        write_png_rgba(std::path::Path::new("/tmp/pic/dvr.png"), &img).unwrap();
    }
}
