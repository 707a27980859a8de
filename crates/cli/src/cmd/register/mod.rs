//! `volmorph register …`: the registration workbench (handles, correspondences, deformation,
//! quality, lungs, ventilation). Every action is one call into `volmorph_register`.

mod args;

use std::path::{Path, PathBuf};

use anyhow::Context;
use volmorph_register::lungs::LungOptions;
use volmorph_register::matching::MatchOptions;
use volmorph_register::phantom::{KnownDeformationOptions, LungPhantomOptions};
use volmorph_register::pipeline::{RegisterOptions, register_files_with, solve_files_with};
use volmorph_register::select::SelectOptions;
use volmorph_register::steps::{self, SubcubeRequest};

pub use self::args::{Command, Step};
use crate::progress;

fn need<'a>(p: &'a Option<PathBuf>, what: &str) -> anyhow::Result<&'a Path> {
    p.as_deref()
        .with_context(|| format!("volmorph register needs {what} (or a step: select, match, …)"))
}

/// Run `volmorph register`.
pub fn run(c: &Command) -> anyhow::Result<()> {
    match &c.step {
        None => {
            let a = &c.run;
            let (f, m, out) = (
                need(&a.fixed, "FIXED")?,
                need(&a.moving, "MOVING")?,
                need(&a.output, "-o OUT_DIR")?,
            );
            let o = RegisterOptions {
                select: SelectOptions::with_count_radius(a.handles, a.radius),
                matching: MatchOptions::default(),
                solve: a.map.solve(),
                dense: a.map.dense(),
            };
            let pb = progress::spinner(format!("registering {} to {}", m.display(), f.display()));
            let landmarks = a.landmarks.files()?;
            let r = register_files_with(
                f,
                m,
                a.mask.as_deref(),
                landmarks.as_ref(),
                out,
                &o,
                &progress::Bar(&pb),
            )
            .context("registration failed")?;
            pb.finish_and_clear();
            say!("{r}\nwrote {} files to {}", r.files.len(), out.display());
        }
        Some(Step::Select(a)) => {
            let o = SelectOptions::with_count_radius(a.handles, a.radius);
            let pb = progress::spinner("selecting handles");
            let n = steps::select_files_with(
                &a.fixed,
                a.mask.as_deref(),
                &a.output,
                &o,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("{n} handles written to {}", a.output.display());
        }
        Some(Step::Match(a)) => {
            let o = MatchOptions {
                levels: a.levels,
                window: a.window,
                search: a.search,
                ..MatchOptions::default()
            };
            let pb = progress::spinner("matching handles");
            let s = steps::match_files_with(
                &a.fixed,
                &a.moving,
                &a.handles,
                &a.output,
                &o,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("{s}");
        }
        Some(Step::Solve(a)) => {
            let pb = progress::spinner(format!("solving {}", a.correspondences.display()));
            let r = solve_files_with(
                &a.fixed,
                &a.moving,
                &a.correspondences,
                a.mask.as_deref(),
                a.landmarks.files()?.as_ref(),
                &a.output,
                &a.map.solve(),
                a.map.dense().as_ref(),
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!(
                "{r}\nwrote {} files to {}",
                r.files.len(),
                a.output.display()
            );
        }
        Some(Step::Quality(a)) => {
            let pb = progress::spinner("checking the map");
            let r = steps::quality_files_with(
                &a.fixed,
                &a.moving,
                &a.map,
                &a.handles.solve(),
                a.landmarks.files()?.as_ref(),
                a.subcube.map(|point| SubcubeRequest {
                    point,
                    half: a.subcube_half,
                }),
                &a.output,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("{r}");
        }
        Some(Step::SegmentLungs(a)) => {
            let o = LungOptions {
                threshold: a.threshold,
                majority_rounds: a.rounds,
                ..LungOptions::default()
            };
            let pb = progress::spinner("segmenting the lungs");
            let r = steps::segment_lungs_files_with(
                &a.ct,
                &a.output,
                a.lobes.as_deref(),
                a.reference.as_deref(),
                &o,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("{r}");
        }
        Some(Step::Ventilation(a)) => {
            let pb = progress::spinner("ventilation");
            let r = steps::ventilation_files_with(
                &a.inhale,
                &a.exhale,
                &a.map,
                &a.labels,
                &a.handles.solve(),
                &a.output,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("{r}");
        }
        Some(Step::Phantom(a)) => {
            let o = LungPhantomOptions {
                dims: crate::args::triple(&a.dims)?,
                spacing: glam::DVec3::from_array(crate::args::triple(&a.spacing)?),
                amplitude: a.amplitude,
                noise: a.noise,
                seed: a.seed,
                ..LungPhantomOptions::default()
            };
            let pb = progress::spinner("lung phantom");
            let n = steps::write_phantom_with(&a.output, &o, &progress::Bar(&pb))?;
            pb.finish_and_clear();
            say!(
                "phantom with {n} landmark pairs written to {}",
                a.output.display()
            );
        }
        Some(Step::KnownPair(a)) => {
            let o = KnownDeformationOptions {
                magnitude: a.magnitude,
                spacing: a.spacing,
                seed: a.seed,
                intensity_change: a.intensity_change,
            };
            let pb = progress::spinner("known pair");
            steps::write_known_pair_with(
                &a.input,
                &a.output,
                &o,
                a.landmarks,
                &progress::Bar(&pb),
            )?;
            pb.finish_and_clear();
            say!("pair written to {}", a.output.display());
        }
    }
    Ok(())
}
