//! The machine's limits, measured: memory bandwidth and floating-point rate, the two roofs
//! that bound every hot path in `docs/performance.md`.
//!
//! `volmorph bench roofline` runs small probes, each on one thread and on every thread of the
//! rayon pool:
//!
//! * **Memory bandwidth** (STREAM's conventions): *read* sums an array
//!   (8 bytes per element), *copy* `c = a` (16 bytes), *triad* `a = b + s·c` (24 bytes).
//!   Write-allocate traffic is not counted, as in STREAM. The arrays are
//!   [`RooflineConfig::megabytes`] MiB each (three of them), far beyond the last-level cache,
//!   and are touched once before the clock starts, by the threads that later use them.
//! * **Floating-point rate**: independent chains of fused multiply-adds in `f64` and `f32`
//!   (the peak: two flops per lane and instruction), and of a multiply followed by an add in
//!   `f64` — the roof of kernels that must stay bit-for-bit equal to their scalar form, which
//!   Rust never contracts into a fused multiply-add. Enough chains run side by side to cover
//!   the operations' latency, so the figure is the issue rate of the floating-point ports.
//!   On x86-64 with AVX2 and FMA the loops run in 256-bit registers, written with
//!   `std::arch` intrinsics (the compiler left the portable `f64` loops scalar); elsewhere
//!   they run as portable code. [`vector_isa`] names the path in use; both give the same bits.
//!
//! Written here rather than taken from a crate: the STREAM kernels are a few lines, and no
//! maintained crate measures a floating-point issue rate; both must run in the same binary,
//! build and thread pool as the kernels they bound.

use std::hint::black_box;
use std::time::Instant;

use rayon::prelude::*;
use serde_json::json;

use crate::timing::{Item, Rate, RateUnit, Report, Unit};
use crate::{BenchError, check_repeat};

/// Default size of each of the three bandwidth arrays, in MiB (768 MiB in all: far beyond
/// any last-level cache of the machines volmorph targets, 32 MiB on the reference machine).
pub const DEFAULT_MEGABYTES: usize = 256;

/// Smallest array size accepted, in MiB: smaller arrays would measure the cache, not memory.
pub const MIN_MEGABYTES: usize = 64;

/// Largest array size accepted, in MiB (three arrays of 4 GiB).
pub const MAX_MEGABYTES: usize = 4096;

/// Iterations of each floating-point chain loop per thread (each iteration issues one
/// operation on every chain): about 0.1 s per run on the reference machine.
const FLOP_ITERATIONS: usize = 1 << 24;

/// `f64` accumulators of the fused multiply-add loop: 8 vectors of 4 lanes, twice the
/// latency × throughput product of two 4-cycle FMA pipes, so the ports never wait.
const FMA_F64_CHAINS: usize = 32;

/// `f32` accumulators of the fused multiply-add loop: 8 vectors of 8 lanes.
const FMA_F32_CHAINS: usize = 64;

/// `f64` accumulators of the multiply-then-add loop: 12 vectors of 4 lanes, covering a
/// multiply and a dependent add (3 + 3 cycles) on two pipes each.
const MUL_ADD_F64_CHAINS: usize = 48;

/// Settings of the roofline probe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RooflineConfig {
    /// Size of each of the three bandwidth arrays, in MiB ([`MIN_MEGABYTES`] to
    /// [`MAX_MEGABYTES`]).
    pub megabytes: usize,
    /// Timed runs per probe.
    pub repeat: usize,
}

impl Default for RooflineConfig {
    fn default() -> Self {
        Self {
            megabytes: DEFAULT_MEGABYTES,
            repeat: 5,
        }
    }
}

impl RooflineConfig {
    /// Check every setting.
    ///
    /// # Errors
    /// [`BenchError::Setting`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), BenchError> {
        BenchError::range("megabytes", self.megabytes, MIN_MEGABYTES..=MAX_MEGABYTES)?;
        check_repeat(self.repeat)
    }
}

/// The measured roofs: the medians of the all-thread probes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roofs {
    /// Triad bandwidth on every thread, GB/s (the memory roof).
    pub bandwidth: f64,
    /// Fused multiply-add rate in `f64` on every thread, Gflop/s (the vector peak).
    pub fma_f64: f64,
    /// Multiply-then-add rate in `f64` on every thread, Gflop/s (the roof of bit-exact
    /// kernels).
    pub mul_add_f64: f64,
}

impl Roofs {
    /// Operational intensity (flops per byte) above which a kernel is bound by the `f64`
    /// multiply-then-add rate rather than by memory.
    #[must_use]
    pub fn ridge(&self) -> f64 {
        self.mul_add_f64 / self.bandwidth
    }
}

/// The instruction set the floating-point loops run with on this machine: `"avx2+fma"` when
/// the CPU has both (x86-64 only), otherwise `"baseline"` (where fused multiply-adds may be
/// library calls, so the FMA rows say little).
#[must_use]
pub fn vector_isa() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return "avx2+fma";
        }
    }
    "baseline"
}

/// Bandwidth arrays, allocated and first touched in parallel (so each thread's pages are its
/// own on machines that place pages where they are first written).
struct Arrays {
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
}

impl Arrays {
    fn new(len: usize) -> Self {
        let fill = |v: f64| {
            let mut x = Vec::with_capacity(len);
            x.par_extend((0..len).into_par_iter().map(move |i| v + (i % 7) as f64));
            x
        };
        Self {
            a: fill(1.0),
            b: fill(2.0),
            c: fill(0.5),
        }
    }
}

/// Elements per parallel task of the bandwidth kernels (1 MiB of `f64`).
const STREAM_TASK: usize = 1 << 17;

/// Sum of `x` in eight lanes (so the compiler may vectorise without reassociating).
fn sum8(x: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let mut chunks = x.chunks_exact(8);
    for c in &mut chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a += v;
        }
    }
    acc.iter().sum::<f64>() + chunks.remainder().iter().sum::<f64>()
}

fn read(a: &[f64], parallel: bool) -> f64 {
    if parallel {
        a.par_chunks(STREAM_TASK).map(sum8).sum()
    } else {
        sum8(a)
    }
}

fn copy(c: &mut [f64], a: &[f64], parallel: bool) {
    if parallel {
        c.par_chunks_mut(STREAM_TASK)
            .zip(a.par_chunks(STREAM_TASK))
            .for_each(|(c, a)| c.copy_from_slice(a));
    } else {
        c.copy_from_slice(a);
    }
}

fn triad(a: &mut [f64], b: &[f64], c: &[f64], s: f64, parallel: bool) {
    let kernel = |a: &mut [f64], b: &[f64], c: &[f64]| {
        for ((a, b), c) in a.iter_mut().zip(b).zip(c) {
            *a = b + s * c;
        }
    };
    if parallel {
        a.par_chunks_mut(STREAM_TASK)
            .zip(b.par_chunks(STREAM_TASK))
            .zip(c.par_chunks(STREAM_TASK))
            .for_each(|((a, b), c)| kernel(a, b, c));
    } else {
        kernel(a, b, c);
    }
}

/// `iterations` rounds of `acc = acc·m + c` as fused multiply-adds on `FMA_F64_CHAINS`
/// independent `f64` accumulators starting at 0, 1, …; returns their sum in chain order (so
/// the loop cannot be dropped). The AVX2 path and the portable one give the same bits.
fn fma_f64(iterations: usize, m: f64, c: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if let Some(s) = avx2::fma_f64(iterations, m, c) {
        return s;
    }
    portable::chains::<FMA_F64_CHAINS, f64>(iterations, |a| a.mul_add(m, c))
}

/// As [`fma_f64`] in `f32` on `FMA_F32_CHAINS` accumulators.
fn fma_f32(iterations: usize, m: f32, c: f32) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if let Some(s) = avx2::fma_f32(iterations, m, c) {
        return s;
    }
    portable::chains::<FMA_F32_CHAINS, f32>(iterations, |a| a.mul_add(m, c))
}

/// `iterations` rounds of `acc = acc·m + c` as a multiply then an add (two roundings, as
/// every bit-exact kernel computes it) on `MUL_ADD_F64_CHAINS` `f64` accumulators; as
/// [`fma_f64`] otherwise.
fn mul_add_f64(iterations: usize, m: f64, c: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if let Some(s) = avx2::mul_add_f64(iterations, m, c) {
        return s;
    }
    portable::chains::<MUL_ADD_F64_CHAINS, f64>(iterations, |a| a * m + c)
}

/// The chain loops written for any target (the compiler vectorises the `f32` one on x86-64,
/// but kept the `f64` ones scalar, hence [`avx2`]).
mod portable {
    /// `iterations` rounds of `acc = step(acc)` on `N` accumulators starting at 0, 1, …,
    /// summed in chain order.
    pub(super) fn chains<const N: usize, T>(iterations: usize, step: impl Fn(T) -> T) -> T
    where
        T: Copy + std::ops::Add<Output = T> + From<u16>,
    {
        let mut acc: [T; N] = std::array::from_fn(|i| T::from(i as u16));
        for _ in 0..iterations {
            for a in &mut acc {
                *a = step(*a);
            }
        }
        acc.into_iter().fold(T::from(0), |s, a| s + a)
    }
}

/// The chain loops in AVX2 registers, written with `std::arch` intrinsics so that every
/// accumulator is a full 256-bit vector: the compiler's own vectorisation of the portable
/// `f64` loops kept them scalar, which made the probe report the scalar issue rate as the
/// `f64` roof. Lane `l` of vector `v` is chain `4v + l` (`8v + l` in `f32`), so the start
/// values and the final sum in chain order equal [`portable::chains`] bit for bit.
///
/// The only `unsafe` code of the crate (allowed here against the workspace's `deny`): calls
/// of `#[target_feature]` functions after the run-time feature check, and unaligned stores
/// of a vector into a local array of its lane count.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx2 {
    use std::arch::x86_64::{
        __m256, __m256d, _mm256_add_pd, _mm256_fmadd_pd, _mm256_fmadd_ps, _mm256_mul_pd,
        _mm256_set1_pd, _mm256_set1_ps, _mm256_setr_pd, _mm256_setr_ps, _mm256_storeu_pd,
        _mm256_storeu_ps,
    };

    use super::{FMA_F32_CHAINS, FMA_F64_CHAINS, MUL_ADD_F64_CHAINS, vector_isa};

    /// `fused` rounds `acc·m + c` in one rounding, otherwise a multiply then an add.
    #[target_feature(enable = "avx2,fma")]
    fn run_f64<const V: usize>(iterations: usize, m: f64, c: f64, fused: bool) -> f64 {
        let (vm, vc) = (_mm256_set1_pd(m), _mm256_set1_pd(c));
        let mut acc: [__m256d; V] = [_mm256_set1_pd(0.0); V];
        for (v, a) in acc.iter_mut().enumerate() {
            let b = (4 * v) as f64;
            *a = _mm256_setr_pd(b, b + 1.0, b + 2.0, b + 3.0);
        }
        if fused {
            for _ in 0..iterations {
                for a in &mut acc {
                    *a = _mm256_fmadd_pd(*a, vm, vc);
                }
            }
        } else {
            for _ in 0..iterations {
                for a in &mut acc {
                    *a = _mm256_add_pd(_mm256_mul_pd(*a, vm), vc);
                }
            }
        }
        let mut s = 0.0;
        for a in &acc {
            let mut lanes = [0.0f64; 4];
            // SAFETY: `lanes` holds the four f64 of one vector; the store is unaligned.
            unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), *a) };
            for l in lanes {
                s += l;
            }
        }
        s
    }

    #[target_feature(enable = "avx2,fma")]
    fn run_f32<const V: usize>(iterations: usize, m: f32, c: f32) -> f32 {
        let (vm, vc) = (_mm256_set1_ps(m), _mm256_set1_ps(c));
        let mut acc: [__m256; V] = [_mm256_set1_ps(0.0); V];
        for (v, a) in acc.iter_mut().enumerate() {
            let b = (8 * v) as f32;
            *a = _mm256_setr_ps(
                b,
                b + 1.0,
                b + 2.0,
                b + 3.0,
                b + 4.0,
                b + 5.0,
                b + 6.0,
                b + 7.0,
            );
        }
        for _ in 0..iterations {
            for a in &mut acc {
                *a = _mm256_fmadd_ps(*a, vm, vc);
            }
        }
        let mut s = 0.0f32;
        for a in &acc {
            let mut lanes = [0.0f32; 8];
            // SAFETY: `lanes` holds the eight f32 of one vector; the store is unaligned.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), *a) };
            for l in lanes {
                s += l;
            }
        }
        s
    }

    /// [`super::fma_f64`] in AVX2 registers, or `None` when the CPU lacks AVX2 or FMA.
    pub(super) fn fma_f64(iterations: usize, m: f64, c: f64) -> Option<f64> {
        // SAFETY: the CPU has AVX2 and FMA (checked by `vector_isa`).
        (vector_isa() == "avx2+fma")
            .then(|| unsafe { run_f64::<{ FMA_F64_CHAINS / 4 }>(iterations, m, c, true) })
    }

    /// [`super::mul_add_f64`] in AVX2 registers, or `None` when the CPU lacks AVX2 or FMA.
    pub(super) fn mul_add_f64(iterations: usize, m: f64, c: f64) -> Option<f64> {
        // SAFETY: the CPU has AVX2 and FMA (checked by `vector_isa`).
        (vector_isa() == "avx2+fma")
            .then(|| unsafe { run_f64::<{ MUL_ADD_F64_CHAINS / 4 }>(iterations, m, c, false) })
    }

    /// [`super::fma_f32`] in AVX2 registers, or `None` when the CPU lacks AVX2 or FMA.
    pub(super) fn fma_f32(iterations: usize, m: f32, c: f32) -> Option<f32> {
        // SAFETY: the CPU has AVX2 and FMA (checked by `vector_isa`).
        (vector_isa() == "avx2+fma")
            .then(|| unsafe { run_f32::<{ FMA_F32_CHAINS / 8 }>(iterations, m, c) })
    }
}

/// Run `f` once on each of `threads` rayon workers at the same time (or on the calling
/// thread alone for one), returning the wall-clock seconds of the slowest.
fn on_threads(threads: usize, f: &(dyn Fn() -> f64 + Sync)) -> f64 {
    let start = Instant::now();
    if threads == 1 {
        black_box(f());
    } else {
        let sum: f64 = (0..threads).into_par_iter().map(|_| f()).sum();
        black_box(sum);
    }
    start.elapsed().as_secs_f64()
}

/// Time `f` `repeat` times.
fn times(repeat: usize, mut f: impl FnMut() -> f64) -> Vec<f64> {
    (0..repeat).map(|_| f()).collect()
}

/// Run the probes and report each one's times and rate, with the roofs as notes.
///
/// # Errors
/// [`BenchError::Setting`] for settings out of range.
pub fn run(config: &RooflineConfig, progress: &mut dyn FnMut(&str)) -> Result<Report, BenchError> {
    let (report, _) = measure(config, progress)?;
    Ok(report)
}

/// As [`run`], also returning the roofs.
///
/// # Errors
/// [`BenchError::Setting`] for settings out of range.
pub fn measure(
    config: &RooflineConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<(Report, Roofs), BenchError> {
    config.validate()?;
    let threads = rayon::current_num_threads().max(1);
    let len = config.megabytes * (1 << 20) / std::mem::size_of::<f64>();
    let bytes = (len * std::mem::size_of::<f64>()) as f64;
    let mut items = Vec::new();
    let counts: &[usize] = if threads == 1 { &[1] } else { &[1, threads] };

    progress("allocating the bandwidth arrays");
    let mut arrays = Arrays::new(len);
    for &n in counts {
        let parallel = n > 1;
        let label = threads_label(n);
        progress(&format!("memory read, {label}"));
        let t = times(config.repeat, || {
            let start = Instant::now();
            black_box(read(&arrays.a, parallel));
            start.elapsed().as_secs_f64()
        });
        items.push(rate_item(format!("memory read, {label}"), t, bytes, true));
        progress(&format!("memory copy, {label}"));
        let t = times(config.repeat, || {
            let Arrays { a, c, .. } = &mut arrays;
            let start = Instant::now();
            copy(c, a, parallel);
            black_box(&c);
            start.elapsed().as_secs_f64()
        });
        items.push(rate_item(
            format!("memory copy, {label}"),
            t,
            2.0 * bytes,
            true,
        ));
        progress(&format!("memory triad, {label}"));
        let t = times(config.repeat, || {
            let Arrays { a, b, c } = &mut arrays;
            let start = Instant::now();
            triad(a, b, c, 0.5, parallel);
            black_box(&a);
            start.elapsed().as_secs_f64()
        });
        items.push(rate_item(
            format!("memory triad, {label}"),
            t,
            3.0 * bytes,
            true,
        ));
    }
    drop(arrays);

    let iters = FLOP_ITERATIONS;
    for &n in counts {
        let label = threads_label(n);
        progress(&format!("f64 fused multiply-add, {label}"));
        let t = times(config.repeat, || {
            on_threads(n, &|| {
                fma_f64(black_box(iters), black_box(0.999_999), black_box(1e-3))
            })
        });
        let flops = (2 * FMA_F64_CHAINS * iters * n) as f64;
        items.push(rate_item(
            format!("f64 fused multiply-add, {label}"),
            t,
            flops,
            false,
        ));
        progress(&format!("f32 fused multiply-add, {label}"));
        let t = times(config.repeat, || {
            on_threads(n, &|| {
                f64::from(fma_f32(
                    black_box(iters),
                    black_box(0.999_9),
                    black_box(1e-3),
                ))
            })
        });
        let flops = (2 * FMA_F32_CHAINS * iters * n) as f64;
        items.push(rate_item(
            format!("f32 fused multiply-add, {label}"),
            t,
            flops,
            false,
        ));
        progress(&format!("f64 multiply then add, {label}"));
        let t = times(config.repeat, || {
            on_threads(n, &|| {
                mul_add_f64(black_box(iters), black_box(0.999_999), black_box(1e-3))
            })
        });
        let flops = (2 * MUL_ADD_F64_CHAINS * iters * n) as f64;
        items.push(rate_item(
            format!("f64 multiply then add, {label}"),
            t,
            flops,
            false,
        ));
    }

    let all = threads_label(*counts.last().unwrap_or(&1));
    let rate_of = |name: &str| {
        items
            .iter()
            .find(|it| it.name == format!("{name}, {all}"))
            .and_then(Item::median_rate)
            .unwrap_or(f64::NAN)
    };
    let roofs = Roofs {
        bandwidth: rate_of("memory triad"),
        fma_f64: rate_of("f64 fused multiply-add"),
        mul_add_f64: rate_of("f64 multiply then add"),
    };
    let description = format!(
        "Roofline probe: memory bandwidth over three {} MiB arrays (STREAM's byte counts, \
         write-allocate not counted) and floating-point issue rate ({} loops), on 1 and {} \
         threads, {} runs each",
        config.megabytes,
        vector_isa(),
        threads,
        config.repeat
    );
    let mut report = Report::new(
        "roofline",
        description,
        vec![
            ("megabytes", json!(config.megabytes)),
            ("vector_isa", json!(vector_isa())),
            ("roof_bandwidth_gbs", json!(roofs.bandwidth)),
            ("roof_fma_f64_gflops", json!(roofs.fma_f64)),
            ("roof_mul_add_f64_gflops", json!(roofs.mul_add_f64)),
        ],
        config.repeat,
        Unit::Milliseconds,
        items,
    );
    report.notes.push(format!(
        "Roofs ({all}): memory {:.1} GB/s (triad); f64 {:.1} Gflop/s fused, {:.1} Gflop/s as \
         multiply then add (bit-exact kernels); ridge {:.2} flop/byte.",
        roofs.bandwidth,
        roofs.fma_f64,
        roofs.mul_add_f64,
        roofs.ridge()
    ));
    Ok((report, roofs))
}

fn threads_label(n: usize) -> String {
    if n == 1 {
        String::from("1 thread")
    } else {
        format!("{n} threads")
    }
}

fn rate_item(name: String, times: Vec<f64>, work: f64, bytes: bool) -> Item {
    let unit = if bytes {
        RateUnit::GigabytesPerSecond
    } else {
        RateUnit::GigaflopsPerSecond
    };
    Item::new(name, times, None).with_rate(Some(Rate { work, unit }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_kernels_compute_what_they_count() {
        let n = 3 * STREAM_TASK + 5;
        for parallel in [false, true] {
            let mut arrays = Arrays::new(n);
            let expected: f64 = arrays.a.iter().sum();
            let got = read(&arrays.a, parallel);
            assert!(
                (got - expected).abs() <= 1e-9 * expected,
                "{got} vs {expected}"
            );
            let Arrays { a, b, c } = &mut arrays;
            copy(c, a, parallel);
            assert_eq!(c, a);
            triad(a, b, c, 0.5, parallel);
            for i in [0, 1, n / 2, n - 1] {
                let c_i = 1.0 + (i % 7) as f64; // c was a copy of a
                assert_eq!(a[i], (2.0 + (i % 7) as f64) + 0.5 * c_i);
            }
        }
    }

    #[test]
    fn chain_loops_converge_to_their_fixed_point() {
        // acc → c / (1 − m) for every chain, whatever its start: the loops did their work.
        let (m, c) = (0.5, 1.0);
        assert!((fma_f64(200, m, c) - FMA_F64_CHAINS as f64 * 2.0).abs() < 1e-9);
        assert!((mul_add_f64(200, m, c) - MUL_ADD_F64_CHAINS as f64 * 2.0).abs() < 1e-9);
        assert!((fma_f32(200, 0.5, 1.0) - FMA_F32_CHAINS as f32 * 2.0).abs() < 1e-3);
        // Zero iterations leave the starting values 0, 1, …, n − 1.
        let n = FMA_F64_CHAINS as f64;
        assert_eq!(fma_f64(0, m, c), n * (n - 1.0) / 2.0);
    }

    #[test]
    fn vector_and_portable_chains_give_the_same_bits() {
        // Rounding-sensitive constants: a wrong lane order, a fused step in the
        // multiply-then-add loop or a lost chain changes the sum's bits.
        let (m, c) = (0.999_999_7, 1.234_567e-3);
        let (m32, c32) = (0.999_97f32, 1.234_567e-3f32);
        for it in [0, 1, 7, 1000] {
            let p64 = portable::chains::<FMA_F64_CHAINS, f64>(it, |a| a.mul_add(m, c));
            let q64 = portable::chains::<MUL_ADD_F64_CHAINS, f64>(it, |a| a * m + c);
            let p32 = portable::chains::<FMA_F32_CHAINS, f32>(it, |a| a.mul_add(m32, c32));
            assert_eq!(fma_f64(it, m, c).to_bits(), p64.to_bits());
            assert_eq!(mul_add_f64(it, m, c).to_bits(), q64.to_bits());
            assert_eq!(fma_f32(it, m32, c32).to_bits(), p32.to_bits());
        }
        // The fused and the two-rounding loops do differ, so the comparison can tell them
        // apart.
        let fused = portable::chains::<MUL_ADD_F64_CHAINS, f64>(1000, |a| a.mul_add(m, c));
        assert_ne!(fused.to_bits(), mul_add_f64(1000, m, c).to_bits());
    }

    #[test]
    fn settings_out_of_range_are_named() {
        let bad = RooflineConfig {
            megabytes: 1,
            repeat: 3,
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("megabytes")
        );
        let bad = RooflineConfig {
            megabytes: DEFAULT_MEGABYTES,
            repeat: 0,
        };
        assert!(bad.validate().unwrap_err().to_string().contains("repeat"));
    }

    #[test]
    fn rates_are_work_over_the_median() {
        let it = rate_item("x".into(), vec![2.0, 1.0, 4.0], 6e9, true);
        assert_eq!(it.median_rate(), Some(3.0));
        let it = rate_item("x".into(), vec![0.0], 1.0, false);
        assert!(it.median_rate().unwrap().is_nan());
    }
}
