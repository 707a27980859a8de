//! How close rendering through a coarse sampled map (McPhail §5.5.1) comes to rendering the
//! fully resampled volume: PSNR per grid size, for a volume deformed by a 200-handle affine
//! MLS map, and the time of each picture.
//!
//! ```text
//! cargo run --release -p volmorph-render --features examples --example deformed_psnr -- VOLUME [SIZE]
//! ```
//!
//! The reference resamples the whole volume through the exact map at every voxel (trilinear
//! pull-back, `volmorph_warp::apply::warp_volume`) and renders it undeformed; each picture
//! under test renders the original volume through the map sampled on an `n³` grid. Both use
//! the CT bone preset (or MRI for non-CT volumes, as `volmorph render` chooses), the anterior
//! view and the same step.
//!
//! Resampling on the volume's own grid interpolates twice (the map's image of a voxel centre
//! falls between voxels, and the picture samples between the resampled voxels), so the
//! resampled reference differs from the exactly deformed volume by more than a fine grid
//! does. The example therefore also reports each picture's PSNR against the picture through
//! the map sampled on [`CONVERGED`]³ nodes: the error of the grid alone.

use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use volmorph_handles::{AffineMls, Weighting};
use volmorph_render::{
    DEFAULT_FOV_Y, DeformedView, DvrOptions, DvrRenderer, DvrVolume, Framing, Orbit, Projection,
    TransferChoice, UpAxis, psnr,
};
use volmorph_testkit::Rng;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};

/// Grid sizes compared.
const GRIDS: [usize; 6] = [5, 9, 17, 33, 49, 65];

/// Nodes per axis of the grid whose picture stands for the exactly deformed volume in the
/// grid-only comparison (twice the finest compared grid).
const CONVERGED: usize = 129;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next().map(PathBuf::from) else {
        eprintln!("usage: deformed_psnr VOLUME [SIZE]");
        std::process::exit(2);
    };
    if !path.is_file() {
        println!("SKIP: {} not found", path.display());
        return Ok(());
    }
    let size: u32 = args.next().map_or(Ok(512), |s| s.parse())?;
    let volume = volmorph_volume_io::read(&path)?;
    let geometry = *volume.geometry();
    let (lo, hi) = geometry.physical_bounds();
    let extent = hi - lo;
    let centre = 0.5 * (lo + hi);

    // 200 handles spread through the box, moved by a smooth bend of a few per cent.
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
    // Pull-back: displayed (target) points to volume (source) points.
    let map = AffineMls::new(
        &targets,
        &sources,
        Weighting::InverseDistance { alpha: 1.0 },
    )?;

    let source = DvrVolume::new(&volume)?;
    let t = Instant::now();
    let background = source.value_range().0;
    let options = WarpOptions {
        background,
        mask: false,
        sampled_nodes: None,
    };
    let resampled = warp_volume(
        &volume,
        &map,
        &geometry,
        WarpMethod::PullbackLinear,
        &options,
    )?;
    println!("resampled exactly in {:.2} s", t.elapsed().as_secs_f64());

    let warped = DvrVolume::new(&resampled.volume)?;
    let transfer = TransferChoice::Auto.resolve(&source)?;
    println!("transfer function {}", transfer.name().unwrap_or("auto"));
    let camera = Orbit::named("anterior", UpAxis::Z)
        .ok_or("no anterior view")?
        .camera(
            (lo, hi),
            Projection::Perspective {
                fov_y: DEFAULT_FOV_Y,
            },
            Framing::Sphere,
            size,
            size,
        )?;
    let opts = DvrOptions::new(transfer);
    let unlit = DvrOptions {
        shading: None,
        ..opts.clone()
    };
    let renderer = DvrRenderer::new(&source, opts.clone())?;
    let reference_renderer = DvrRenderer::new(&warped, opts)?;
    // Unlit too: gradients of the resampled volume (differences of twice-interpolated,
    // re-quantised voxels) differ from the exact deformed gradient more than the colours do.
    let renderer_unlit = DvrRenderer::new(&source, unlit.clone())?;
    let reference_unlit = DvrRenderer::new(&warped, unlit)?.render(&camera)?;
    let reference = reference_renderer.render(&camera)?;
    let t = Instant::now();
    let plain = renderer.render(&camera)?;
    let plain_time = t.elapsed().as_secs_f64();
    println!(
        "undeformed picture {:.1} ms; PSNR of the undeformed picture against the reference \
         {:.1} dB (how much the deformation shows)",
        plain_time * 1e3,
        psnr(&plain, &reference)?
    );
    let converged = renderer.render_deformed(
        &DeformedView::from_map(&source, &map, [CONVERGED; 3])?,
        &camera,
    )?;
    println!(
        "grid   sample map (ms)   render (ms)   PSNR (dB)   unlit PSNR (dB)   PSNR vs {CONVERGED}³ (dB)"
    );
    let mut first_40 = None;
    let mut first_40_grid = None;
    for n in GRIDS {
        let t = Instant::now();
        let view = DeformedView::from_map(&source, &map, [n; 3])?;
        let sample = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let picture = renderer.render_deformed(&view, &camera)?;
        let render = t.elapsed().as_secs_f64();
        let db = psnr(&picture, &reference)?;
        let db_unlit = psnr(
            &renderer_unlit.render_deformed(&view, &camera)?,
            &reference_unlit,
        )?;
        let db_grid = psnr(&picture, &converged)?;
        if db >= 40.0 && first_40.is_none() {
            first_40 = Some(n);
        }
        if db_grid >= 40.0 && first_40_grid.is_none() {
            first_40_grid = Some(n);
        }
        println!(
            "{n:>3}³   {:>15.1}   {:>11.1}   {db:>9.1}   {db_unlit:>15.1}   {db_grid:>20.1}",
            sample * 1e3,
            render * 1e3
        );
    }
    let last = GRIDS[GRIDS.len() - 1];
    match first_40 {
        Some(n) => println!("40 dB against the resampled volume reached at {n}³"),
        None => println!("40 dB against the resampled volume not reached up to {last}³"),
    }
    match first_40_grid {
        Some(n) => println!("40 dB against the {CONVERGED}³ grid reached at {n}³"),
        None => println!("40 dB against the {CONVERGED}³ grid not reached up to {last}³"),
    }
    Ok(())
}
