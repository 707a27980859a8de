//! The packed classification marching cubes scans: one bit per sample (set when the sample is
//! inside), 64 samples of a grid row to a word, and a summary per row (all outside, all
//! inside, mixed).
//!
//! Marching cubes spends its time on the many cells that no surface crosses. With the samples
//! packed, a row's crossed x edges are the set bits of `row ^ (row >> 1)`, the crossed y and
//! z edges those of the XOR of two rows, and the cells with corners on both sides those of a
//! few ORs of such words; iterating the set bits in increasing order visits exactly the edges
//! and cells the per-sample scan visited, in the same order, so the surface is the same bit
//! for bit while the cost per empty cell drops to a fraction of an instruction.
//!
//! Written here rather than taken from a crate: the packing must apply marching cubes' own
//! inside rule (`≤` or `≥` the level in `f64`, NaN outside) to every voxel type, and the scans
//! are a few word operations each.

use multiversion::multiversion;
use rayon::prelude::*;
use volmorph_volume::{VolumeError, Voxel};

use crate::ContourError;
use crate::marching::{ALL_IN, ALL_OUT, Field, MIXED};

/// Samples per packed word.
const WORD: usize = 64;

/// The classification of every sample of a field, packed (see the module documentation).
pub(crate) struct Classes {
    /// Word `w` of row `j` of plane `k` at `(k·ny + j)·wpr + w`; bit `b` is sample
    /// `i = 64·w + b`; bits at `i ≥ nx` are zero.
    words: Vec<u64>,
    /// Summary of row `j` of plane `k` at `k·ny + j`: [`ALL_OUT`], [`ALL_IN`] or [`MIXED`].
    rows: Vec<u8>,
    /// Words per row.
    wpr: usize,
    nx: usize,
    ny: usize,
}

impl Classes {
    /// Classify every sample of `field`, plane by plane in parallel, advancing `progress` by
    /// one step per plane and stopping between planes when it is cancelled (the caller
    /// checks).
    ///
    /// # Errors
    /// [`ContourError::Volume`] when the packed planes (one bit per sample) exceed the
    /// allocation limit.
    pub(crate) fn new<T: Voxel>(
        field: &Field<'_, T>,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<Self, ContourError> {
        let (nx, ny, nz) = (field.nx, field.ny, field.nz);
        let wpr = nx.div_ceil(WORD);
        let len = volmorph_io::checked_len(&[wpr, ny, nz], size_of::<u64>())
            .map_err(|e| ContourError::Volume(VolumeError::Io(e)))?;
        let mut words = vec![0u64; len];
        let mut rows = vec![ALL_OUT; ny * nz];
        let plane = nx * ny;
        let (level, below) = (field.level, field.below);
        words
            .par_chunks_mut(wpr * ny)
            .zip(rows.par_chunks_mut(ny))
            .enumerate()
            .for_each(|(k, (words, rows))| {
                if progress.is_cancelled() {
                    return;
                }
                let src = &field.data[k * plane..(k + 1) * plane];
                for ((out, summary), row) in words
                    .chunks_exact_mut(wpr)
                    .zip(rows.iter_mut())
                    .zip(src.chunks_exact(nx))
                {
                    pack_row(row, level, below, out);
                    *summary = summarise(out, nx);
                }
                progress.advance(1);
            });
        Ok(Self {
            words,
            rows,
            wpr,
            nx,
            ny,
        })
    }

    /// Words per row.
    #[inline]
    pub(crate) fn wpr(&self) -> usize {
        self.wpr
    }

    /// The packed row `j` of plane `k`.
    #[inline]
    pub(crate) fn row(&self, k: usize, j: usize) -> &[u64] {
        let at = (k * self.ny + j) * self.wpr;
        &self.words[at..at + self.wpr]
    }

    /// The summary of row `j` of plane `k`.
    #[inline]
    pub(crate) fn summary(&self, k: usize, j: usize) -> u8 {
        self.rows[k * self.ny + j]
    }

    /// The crossed x edges of a packed row, word `w`: bit `b` set when samples `i = 64w + b`
    /// and `i + 1` (both in the row, so `i < nx − 1`) lie on different sides.
    #[inline]
    pub(crate) fn x_crossings(&self, row: &[u64], w: usize) -> u64 {
        (row[w] ^ shifted_down(row, w)) & edge_mask(w, self.nx)
    }

    /// Calls `f(i)`, in increasing order, for every cell between row pair `(b0, b1)` of one
    /// plane and `(t0, t1)` of the next whose eight corners do not all lie on one side; `i`
    /// is the cell's lowest corner sample (`i < nx − 1`). A cell is uniform exactly when both
    /// its corner columns are (all four corners as the column's `b0` corner) and the two `b0`
    /// corners agree. Each word's column differences are computed once and carried to the
    /// next word, whose first column is the last cell's right side.
    #[inline]
    pub(crate) fn for_each_active_cell(&self, rows: [&[u64]; 4], mut f: impl FnMut(usize)) {
        let b0 = rows[0];
        let mut e = column_differences(rows, 0);
        for w in 0..self.wpr {
            let e_next = column_differences(rows, w + 1);
            let columns = (e | (e >> 1) | (e_next << 63)) & edge_mask(w, self.nx);
            for_each_bit(columns | self.x_crossings(b0, w), w, &mut f);
            e = e_next;
        }
    }
}

/// The marching-cubes case of the cell whose lowest corner is sample `i` of row quadruple
/// `[b0, b1, t0, t1]`: corner bits 0, 2, 4, 6 are the `i` column of `b0`, `b1`, `t0`, `t1`,
/// bits 1, 3, 5, 7 the `i + 1` column (the table's corner numbering, x fastest).
#[inline]
pub(crate) fn cell_case(rows: [&[u64]; 4], i: usize) -> u8 {
    let bit = |row: &[u64], i: usize| ((row[i / WORD] >> (i % WORD)) & 1) as u8;
    let column = |i: usize| {
        bit(rows[0], i) | (bit(rows[1], i) << 2) | (bit(rows[2], i) << 4) | (bit(rows[3], i) << 6)
    };
    column(i) | (column(i + 1) << 1)
}

/// Columns of word `w` (of a row quadruple `[b0, b1, t0, t1]`) whose four corners do not all
/// equal the `b0` corner; zero past the row's end.
#[inline]
fn column_differences([b0, b1, t0, t1]: [&[u64]; 4], w: usize) -> u64 {
    match b0.get(w) {
        Some(&b) => (b ^ b1[w]) | (b ^ t0[w]) | (b ^ t1[w]),
        None => 0,
    }
}

/// Word `w` of `row` shifted down by one sample: bit `b` holds sample `64w + b + 1`.
#[inline]
fn shifted_down(row: &[u64], w: usize) -> u64 {
    (row[w] >> 1) | row.get(w + 1).map_or(0, |n| n << 63)
}

/// Bits of word `w` that stand for an edge or cell start `i = 64w + b < nx − 1`.
#[inline]
fn edge_mask(w: usize, nx: usize) -> u64 {
    let edges = nx - 1;
    let start = w * WORD;
    if edges >= start + WORD {
        u64::MAX
    } else if edges <= start {
        0
    } else {
        (1u64 << (edges - start)) - 1
    }
}

/// Calls `f(64·w + b)` for every set bit `b` of `bits`, in increasing order.
#[inline]
pub(crate) fn for_each_bit(mut bits: u64, w: usize, mut f: impl FnMut(usize)) {
    while bits != 0 {
        f(w * WORD + bits.trailing_zeros() as usize);
        bits &= bits - 1;
    }
}

/// Pack one row: bit `i` of `out` set when `src[i]` is inside (`≤ level` when `below`, else
/// `≥ level`, compared in `f64`; NaN is outside). Compiled for the baseline target and for
/// x86-64 with AVX2, chosen at run time.
#[multiversion(targets("x86_64+avx2+fma"))]
fn pack_row<T: Voxel>(src: &[T], level: f64, below: bool, out: &mut [u64]) {
    let mut chunks = src.chunks_exact(WORD);
    let mut words = out.iter_mut();
    // Whole words with a constant trip count (so the compiler unrolls and vectorises them),
    // the comparison hoisted out of the loops.
    // (`chunks` first: `zip` takes from its left side before the right one runs out.)
    for (chunk, o) in chunks.by_ref().zip(words.by_ref()) {
        *o = if below {
            pack_word(chunk, |v| v <= level)
        } else {
            pack_word(chunk, |v| v >= level)
        };
    }
    let rest = chunks.remainder();
    if let Some(o) = words.next() {
        *o = if below {
            pack_word(rest, |v| v <= level)
        } else {
            pack_word(rest, |v| v >= level)
        };
    }
}

/// Bit `b` set when `inside(chunk[b])`, for up to 64 samples.
#[inline(always)]
fn pack_word<T: Voxel>(chunk: &[T], inside: impl Fn(f64) -> bool) -> u64 {
    let mut m = 0u64;
    for (b, v) in chunk.iter().enumerate() {
        m |= u64::from(inside(v.to_f64())) << b;
    }
    m
}

/// The summary of a packed row of `nx` samples.
fn summarise(row: &[u64], nx: usize) -> u8 {
    let inside: u32 = row.iter().map(|w| w.count_ones()).sum();
    if inside == 0 {
        ALL_OUT
    } else if inside as usize == nx {
        ALL_IN
    } else {
        MIXED
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edge_masks_cover_exactly_the_edges() {
        for nx in [2usize, 3, 63, 64, 65, 127, 128, 129, 200] {
            let wpr = nx.div_ceil(WORD);
            let count: u32 = (0..wpr).map(|w| edge_mask(w, nx).count_ones()).sum();
            assert_eq!(count as usize, nx - 1, "nx {nx}");
        }
    }

    #[test]
    fn packed_rows_agree_with_the_per_sample_rule() {
        let mut rng = volmorph_testkit::Rng::new(7);
        for nx in [2usize, 5, 64, 65, 130] {
            let src: Vec<f32> = (0..nx)
                .map(|i| match i % 5 {
                    0 => 0.5,
                    1 => f32::NAN,
                    _ => rng.range(0.0, 1.0) as f32,
                })
                .collect();
            for below in [false, true] {
                let mut out = vec![0u64; nx.div_ceil(WORD)];
                pack_row(&src, 0.5, below, &mut out);
                for (i, v) in src.iter().enumerate() {
                    let inside = if below { *v <= 0.5 } else { *v >= 0.5 };
                    assert_eq!(
                        out[i / WORD] >> (i % WORD) & 1 == 1,
                        inside,
                        "nx {nx} i {i}"
                    );
                }
                // No stray bits beyond the row.
                let total: u32 = out.iter().map(|w| w.count_ones()).sum();
                let expected = src
                    .iter()
                    .filter(|v| if below { **v <= 0.5 } else { **v >= 0.5 })
                    .count();
                assert_eq!(total as usize, expected);
            }
        }
    }

    #[test]
    fn bits_are_visited_in_increasing_order() {
        let mut seen = Vec::new();
        for_each_bit(0b1010_0001 | (1 << 63), 2, |i| seen.push(i));
        assert_eq!(seen, vec![128, 133, 135, 191]);
    }
}
