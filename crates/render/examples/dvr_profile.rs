//! One composite picture of a volume, as `volmorph render VOLUME --transfer ct-bone --view
//! anterior` takes it, repeated: a small target for `valgrind --tool=callgrind` that builds
//! with the render crate alone.
//!
//! ```text
//! cargo build --release -p volmorph-render --features examples --example dvr_profile
//! valgrind --tool=callgrind target/release/examples/dvr_profile VOLUME [SIZE] [PICTURES] [deformed] [OUT.png]
//! ```
//!
//! With `deformed`, the volume is shown through a 200-handle affine MLS bend sampled on the
//! default 33³ grid (the bend of the `deformed_psnr` example). Prints the median wall time per
//! picture; the picture's instructions are those of `row_kernel` (inclusive) over the count.

use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use volmorph_handles::{AffineMls, Weighting};
use volmorph_render::{
    DvrVolume, Orbit, PictureSpec, TransferChoice, UpAxis, VolumePictures, write_png_rgba,
};
use volmorph_testkit::Rng;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next().map(PathBuf::from) else {
        eprintln!("usage: dvr_profile VOLUME [SIZE] [PICTURES] [deformed] [OUT.png]");
        std::process::exit(2);
    };
    let size: u32 = args.next().map_or(Ok(512), |s| s.parse())?;
    let pictures: usize = args.next().map_or(Ok(1), |s| s.parse())?;
    let deformed = args.next().is_some_and(|s| s == "deformed");
    let out = args.next().map(PathBuf::from);
    let volume = volmorph_volume_io::read(&path)?;
    let (lo, hi) = volume.geometry().physical_bounds();
    let map = deformed
        .then(|| {
            let (extent, centre) = (hi - lo, 0.5 * (lo + hi));
            let mut rng = Rng::new(20_241_201);
            let sources: Vec<DVec3> = (0..200).map(|_| rng.point_in(lo, hi)).collect();
            let targets: Vec<DVec3> = sources
                .iter()
                .map(|&s| {
                    let q = (s - centre) / extent;
                    s + DVec3::new(
                        0.04 * extent.x * (q.z * std::f64::consts::PI).sin(),
                        0.03 * extent.y * (q.x * std::f64::consts::PI).cos(),
                        0.0,
                    )
                })
                .collect();
            AffineMls::new(
                &targets,
                &sources,
                Weighting::InverseDistance { alpha: 1.0 },
            )
        })
        .transpose()?;
    let dvr = DvrVolume::new(&volume)?;
    let spec = PictureSpec {
        transfer: TransferChoice::parse("ct-bone")?,
        size: (size, size),
        ..PictureSpec::new(Orbit::parse("anterior", UpAxis::Z)?)
    };
    let pics = VolumePictures::new(
        &dvr,
        map.as_ref().map(|m| m as &dyn volmorph_deform::SpaceMap),
        spec,
    )?;
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..pictures {
        let t = Instant::now();
        last = Some(pics.frame(0)?);
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{pictures} picture(s) of {size}², median {:.1} ms",
        times[times.len() / 2] * 1e3
    );
    if let (Some(p), Some(img)) = (out, last) {
        write_png_rgba(&p, &img)?;
    }
    Ok(())
}
