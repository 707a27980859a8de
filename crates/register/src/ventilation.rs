//! Ventilation from the deformation (McPhail's thesis §5.7), and the intensity-based estimate
//! beside it.
//!
//! For the map `φ` from the inhale scan `I` (fixed) to the exhale scan `E` (moving),
//! `jac(x) = vol(φ(B_x)) / vol(B_x) = det Dφ(x)` is the local volume ratio exhale/inhale: below 1
//! where the lung deflates. Beyond the thesis, the two scans' densities give an independent
//! estimate: lung tissue mass is conserved, and a voxel of HU `h` holds `(1000 + h)/1000` of
//! tissue per unit volume (air −1000, tissue 0), so the volume ratio is
//! `(1000 + h_I(x)) / (1000 + h_E(φ(x)))` (Simon 2000; Fuld et al. 2008), computed on both
//! images smoothed by `smoothing` binomial passes (mass is conserved over regions, not single
//! voxels). The specific air volume `sVol = −h / (1000 + h)` (ml of air per g of tissue) changes
//! by `sVol_E − sVol_I`. Both are reported per voxel and per lobe (mean, standard deviation,
//! percentiles, histogram).

use rayon::prelude::*;
use serde::Serialize;
use volmorph_deform::SpaceMap;
use volmorph_volume::Volume;

use crate::RegisterError;
use crate::image::{same_grid, smooth};
use crate::phantom::lobe;

/// Histogram of `jac` per lobe: this many bins over `[0, 2]`.
pub const HISTOGRAM_BINS: usize = 40;

/// Distribution of one quantity over a lobe.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Distribution {
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub sd: f64,
    /// 5th, 25th, 50th, 75th and 95th percentiles.
    pub percentiles: [f64; 5],
}

impl Distribution {
    fn of(mut v: Vec<f64>) -> Self {
        if v.is_empty() {
            return Self {
                mean: f64::NAN,
                sd: f64::NAN,
                percentiles: [f64::NAN; 5],
            };
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((p * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        Self {
            mean,
            sd,
            percentiles: [q(0.05), q(0.25), q(0.5), q(0.75), q(0.95)],
        }
    }
}

/// Ventilation of one lobe (or any labelled region).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LobeVentilation {
    /// Label.
    pub label: u8,
    /// Name (`RUL` … for the lobe labels, `label N` otherwise).
    pub name: String,
    /// Voxels.
    pub voxels: usize,
    /// `jac = det Dφ`.
    pub jacobian: Distribution,
    /// Histogram of `jac` over `[0, 2]` in [`HISTOGRAM_BINS`] bins (values beyond go to the end
    /// bins).
    pub histogram: Vec<usize>,
    /// Mass-conservation volume ratio from the HU values.
    pub hu_volume_ratio: Distribution,
    /// Change of specific air volume `sVol_E − sVol_I`, ml/g.
    pub specific_volume_change: Distribution,
}

/// Ventilation maps and per-region statistics.
#[derive(Debug, Clone)]
pub struct Ventilation {
    /// `jac(x)` on the inhale grid.
    pub jacobian: Volume<f32>,
    /// HU-based volume ratio on the inhale grid (NaN outside the labels).
    pub hu_ratio: Volume<f32>,
    /// Per label present, in label order.
    pub regions: Vec<LobeVentilation>,
}

/// Ventilation of `map` (inhale → exhale) over the non-zero `labels` (inhale grid).
/// `exhale_warped` is the exhale scan resampled onto the inhale grid through the map.
///
/// # Errors
/// [`RegisterError::Mismatch`] if the three volumes are not on one grid,
/// [`RegisterError::Warp`] if the Jacobian map fails.
pub fn ventilation(
    map: &dyn SpaceMap,
    inhale: &Volume<f32>,
    exhale_warped: &Volume<f32>,
    labels: &Volume<u8>,
    smoothing: usize,
) -> Result<Ventilation, RegisterError> {
    same_grid(inhale.geometry(), exhale_warped.geometry(), "warped exhale")?;
    same_grid(inhale.geometry(), labels.geometry(), "labels")?;
    let jac = volmorph_warp::jacobian::jacobian_determinant(map, inhale.geometry())?;
    let (mut si, mut se) = (inhale.clone(), exhale_warped.clone());
    for _ in 0..smoothing {
        si = smooth(&si);
        se = smooth(&se);
    }
    let l = labels.data();
    let ratio: Vec<f32> = si
        .data()
        .par_iter()
        .zip(se.data().par_iter())
        .zip(l.par_iter())
        .map(|((&a, &b), &lab)| {
            let (a, b) = (f64::from(a), f64::from(b));
            if lab == 0 || a <= -1000.0 || b <= -1000.0 {
                f32::NAN
            } else {
                ((1000.0 + a) / (1000.0 + b)) as f32
            }
        })
        .collect();
    let svol = |h: f64| -h / (1000.0 + h);
    let mut regions = Vec::new();
    for label in 1..=u8::MAX {
        let idx: Vec<usize> = (0..l.len()).filter(|&n| l[n] == label).collect();
        if idx.is_empty() {
            continue;
        }
        let j: Vec<f64> = idx.iter().map(|&n| f64::from(jac.data()[n])).collect();
        let mut histogram = vec![0usize; HISTOGRAM_BINS];
        for &v in &j {
            let b = ((v / 2.0 * HISTOGRAM_BINS as f64).floor().max(0.0) as usize)
                .min(HISTOGRAM_BINS - 1);
            histogram[b] += 1;
        }
        let r: Vec<f64> = idx
            .iter()
            .map(|&n| f64::from(ratio[n]))
            .filter(|v| v.is_finite())
            .collect();
        let s: Vec<f64> = idx
            .iter()
            .filter(|&&n| ratio[n].is_finite())
            .map(|&n| svol(f64::from(se.data()[n])) - svol(f64::from(si.data()[n])))
            .collect();
        regions.push(LobeVentilation {
            label,
            name: lobe::NAMES
                .get(label as usize)
                .map_or_else(|| format!("label {label}"), |s| (*s).to_string()),
            voxels: idx.len(),
            jacobian: Distribution::of(j),
            histogram,
            hu_volume_ratio: Distribution::of(r),
            specific_volume_change: Distribution::of(s),
        });
        if label == u8::MAX {
            break;
        }
    }
    Ok(Ventilation {
        jacobian: jac,
        hu_ratio: Volume::new(*inhale.geometry(), ratio)?,
        regions,
    })
}
