//! The isosurface suite: marching cubes and dual contouring of the sphere phantom's signed
//! distance field at level 0.

use serde_json::json;
use volmorph_contour::{DcOptions, McOptions, dual_contouring, marching_cubes};
use volmorph_volume::Volume;
use volmorph_volume::phantom::{self, Phantom};

use crate::targets::ISSUE_3_MARCHING_CUBES;
use crate::timing::{Case, Report, Unit, measure_all};
use crate::{BenchError, MAX_SIZE, check_repeat};

/// Voxels per axis at which the marching-cubes target is stated.
pub const TARGET_SIZE: usize = 256;

/// Settings of the isosurface suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IsosurfaceConfig {
    /// Voxels per axis of the distance field (a cube), 4 to [`MAX_SIZE`].
    pub size: usize,
    /// Timed runs per case, 1 to [`crate::MAX_REPEAT`].
    pub repeat: usize,
}

impl Default for IsosurfaceConfig {
    fn default() -> Self {
        Self {
            size: TARGET_SIZE,
            repeat: 5,
        }
    }
}

impl IsosurfaceConfig {
    /// Check every setting against its range.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        BenchError::range("size", self.size, 4..=MAX_SIZE)?;
        check_repeat(self.repeat)
    }
}

/// The input: the sphere phantom's signed distance (`f32`, negative inside) on a `size³`
/// grid; at 256³ its zero set has about 300 000 triangles.
#[derive(Debug)]
pub struct IsosurfaceInputs {
    /// The distance field.
    pub field: Volume<f32>,
    /// Voxels per axis.
    pub size: usize,
}

impl IsosurfaceInputs {
    /// Build the field.
    ///
    /// # Errors
    /// [`BenchError::Volume`] when it does not fit.
    pub fn new(config: &IsosurfaceConfig) -> Result<Self, BenchError> {
        Ok(Self {
            field: phantom::signed_distance(Phantom::Sphere, [config.size; 3])?,
            size: config.size,
        })
    }

    /// Marching cubes (target at [`TARGET_SIZE`]) and dual contouring with the default
    /// feature threshold, each counting its triangles.
    #[must_use]
    pub fn cases(&self) -> Vec<Case<'_>> {
        let mc = McOptions { inside_below: true };
        let dc = DcOptions {
            inside_below: true,
            ..DcOptions::default()
        };
        vec![
            Case::call_counting(
                "marching cubes",
                "marching_cubes",
                move || Ok(marching_cubes(&self.field, 0.0, &mc)?),
                |s| s.mesh.face_count(),
            )
            .with_target((self.size == TARGET_SIZE).then_some(ISSUE_3_MARCHING_CUBES)),
            Case::call_counting(
                "dual contouring",
                "dual_contouring",
                move || Ok(dual_contouring(&self.field, 0.0, &dc)?),
                |s| s.mesh.face_count(),
            ),
        ]
    }

    /// Measured by the criterion benches only: dual contouring with the QEF solved in every
    /// cell (feature threshold 0).
    #[must_use]
    pub fn extra_cases(&self) -> Vec<Case<'_>> {
        let dc = DcOptions {
            inside_below: true,
            feature_angle: 0.0,
            ..DcOptions::default()
        };
        vec![Case::call_counting(
            "dual contouring, QEF everywhere",
            "dual_contouring_qef_everywhere",
            move || Ok(dual_contouring(&self.field, 0.0, &dc)?),
            |s| s.mesh.face_count(),
        )]
    }
}

/// Run the isosurface suite; `progress` hears what is being built or timed.
///
/// # Errors
/// [`BenchError::Setting`] for a setting out of range, or the first case that fails.
pub fn run(
    config: &IsosurfaceConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<Report, BenchError> {
    config.validate()?;
    progress(&format!(
        "building the sphere distance field {0}x{0}x{0}",
        config.size
    ));
    let inputs = IsosurfaceInputs::new(config)?;
    let items = measure_all(inputs.cases(), config.repeat, progress)?;
    let description = format!(
        "sphere signed distance {n}x{n}x{n} (f32), level 0, {r} runs each, {t} threads",
        n = config.size,
        r = config.repeat,
        t = rayon::current_num_threads(),
    );
    let mut report = Report::new(
        "isosurface",
        description,
        vec![("size", json!(config.size)), ("lattice", json!(null))],
        config.repeat,
        Unit::Seconds,
        items,
    );
    if config.size != TARGET_SIZE {
        report
            .notes
            .push(format!("(targets are stated for a {TARGET_SIZE}^3 field)"));
    }
    Ok(report)
}
