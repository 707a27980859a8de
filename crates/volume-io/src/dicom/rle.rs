//! RLE Lossless (PS3.5 Annex G) frames of 32-bit greyscale samples, the encoding of RT Dose
//! grids stored compressed. Written here because the dicom-rs RLE decoder reads 8- and
//! 16-bit samples only; 8 and 16 bits still go through dicom-rs.
//!
//! A frame is one fragment: a 64-byte header (the segment count, then 15 little-endian
//! 32-bit segment offsets from the fragment's start) and the segments, each a PackBits byte
//! stream (G.3.1: a header byte `n` in 0..=127 copies the next `n + 1` bytes, −127..=−1
//! repeats the next byte `1 − n` times, −128 does nothing). A 32-bit sample has four
//! segments, most significant byte first (G.2), each decoding to `rows · columns` bytes.

use volmorph_volume::VolumeError;

/// Bytes of the RLE header (G.5: one segment count and 15 offsets).
const HEADER_BYTES: usize = 64;

/// Decode one RLE fragment of `pixels` 32-bit samples into little-endian bytes (the layout
/// of native 32-bit pixel data).
///
/// # Errors
/// A header that does not declare 4 segments, offsets outside the fragment or out of order,
/// or a segment that decodes to fewer than `pixels` bytes; each names `what`.
pub(super) fn decode_u32_frame(
    fragment: &[u8],
    pixels: usize,
    what: &str,
) -> Result<Vec<u8>, VolumeError> {
    let bad = |m: String| super::err(format!("{what}: RLE pixel data: {m}"));
    if fragment.len() < HEADER_BYTES {
        return Err(bad(format!(
            "a fragment of {} bytes is shorter than the 64-byte RLE header",
            fragment.len()
        )));
    }
    let word = |i: usize| {
        u32::from_le_bytes([
            fragment[4 * i],
            fragment[4 * i + 1],
            fragment[4 * i + 2],
            fragment[4 * i + 3],
        ]) as usize
    };
    let segments = word(0);
    if segments != 4 {
        return Err(bad(format!(
            "{segments} segments for 32-bit samples (one sample per pixel needs 4)"
        )));
    }
    let offsets: Vec<usize> = (1..=4).map(word).collect();
    let mut out = vec![
        0u8;
        pixels
            .checked_mul(4)
            .ok_or_else(|| bad("too many pixels".into()))?
    ];
    for (s, &start) in offsets.iter().enumerate() {
        let end = offsets.get(s + 1).copied().unwrap_or(fragment.len());
        if start < HEADER_BYTES || start > end || end > fragment.len() {
            return Err(bad(format!(
                "segment {} spans bytes {start}..{end} of a {}-byte fragment",
                s + 1,
                fragment.len()
            )));
        }
        // Segment s holds byte 3 − s of each little-endian sample.
        let lane = 3 - s;
        let got = unpack_bits(&fragment[start..end], pixels, |i, b| out[4 * i + lane] = b);
        if got < pixels {
            return Err(bad(format!(
                "segment {} decodes to {got} bytes, {pixels} expected (Rows × Columns)",
                s + 1
            )));
        }
    }
    Ok(out)
}

/// PackBits-decode `data`, calling `put(i, byte)` for output bytes `0..limit`; returns how
/// many bytes were produced (at most `limit`; the rest of `data`, such as a pad byte, is
/// ignored once `limit` is reached, and a run cut short by the end of `data` ends there).
fn unpack_bits(data: &[u8], limit: usize, mut put: impl FnMut(usize, u8)) -> usize {
    let (mut i, mut n) = (0usize, 0usize);
    while i < data.len() && n < limit {
        let h = data[i] as i8;
        i += 1;
        if h >= 0 {
            let len = (h as usize + 1).min(data.len() - i).min(limit - n);
            for &b in &data[i..i + len] {
                put(n, b);
                n += 1;
            }
            i += h as usize + 1;
        } else if h != -128 {
            let Some(&b) = data.get(i) else { break };
            i += 1;
            for _ in 0..(1 - h as isize) as usize {
                if n == limit {
                    break;
                }
                put(n, b);
                n += 1;
            }
        }
    }
    n
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// PackBits-encode `data` (runs of 3 or more repeated, literals otherwise), as an RLE
    /// encoder following G.3.1 does; used to build test files.
    pub(crate) fn pack_bits(data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut i = 0;
        while i < data.len() {
            let run = data[i..]
                .iter()
                .take(128)
                .take_while(|&&b| b == data[i])
                .count();
            if run >= 3 {
                out.push((1 - run as isize) as i8 as u8);
                out.push(data[i]);
                i += run;
                continue;
            }
            let start = i;
            while i < data.len() && i - start < 128 {
                let r = data[i..]
                    .iter()
                    .take(3)
                    .take_while(|&&b| b == data[i])
                    .count();
                if r >= 3 {
                    break;
                }
                i += 1;
            }
            out.push((i - start - 1) as u8);
            out.extend_from_slice(&data[start..i]);
        }
        if out.len() % 2 == 1 {
            out.push(0x80); // a no-op pad byte: segments have even length
        }
        out
    }

    /// An RLE fragment of 32-bit `samples` (G.2: four segments, most significant byte first).
    pub(crate) fn rle_u32_fragment(samples: &[u32]) -> Vec<u8> {
        let segments: Vec<Vec<u8>> = (0..4)
            .map(|s| {
                pack_bits(
                    &samples
                        .iter()
                        .map(|v| (v >> (24 - 8 * s)) as u8)
                        .collect::<Vec<_>>(),
                )
            })
            .collect();
        let mut header = vec![0u8; HEADER_BYTES];
        header[..4].copy_from_slice(&4u32.to_le_bytes());
        let mut at = HEADER_BYTES;
        for (s, seg) in segments.iter().enumerate() {
            header[4 + 4 * s..8 + 4 * s].copy_from_slice(&(at as u32).to_le_bytes());
            at += seg.len();
        }
        header.extend(segments.concat());
        header
    }

    #[test]
    fn rle_frames_of_32_bit_samples_decode_to_their_values() {
        // Runs, literals, runs longer than 128 and values using every byte.
        let mut samples: Vec<u32> = (0..300u32).map(|i| i.wrapping_mul(2_654_435_761)).collect();
        samples.extend([7u32; 200]);
        samples.extend((0..55).map(|i| 0xFFFF_0000 + i));
        let frame = rle_u32_fragment(&samples);
        let bytes = decode_u32_frame(&frame, samples.len(), "f").unwrap();
        let back: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(back, samples);
    }

    #[test]
    fn broken_rle_frames_are_refused_naming_the_fault() {
        let samples = [1u32, 2, 3, 4, 5, 6];
        let good = rle_u32_fragment(&samples);
        let msg = |f: &[u8], n| decode_u32_frame(f, n, "dose.dcm").unwrap_err().to_string();
        assert!(msg(&good[..40], 6).contains("shorter than the 64-byte"));
        let mut three = good.clone();
        three[0] = 3;
        assert!(msg(&three, 6).contains("3 segments"));
        let mut outside = good.clone();
        outside[8..12].copy_from_slice(&10_000u32.to_le_bytes());
        let m = msg(&outside, 6);
        assert!(m.contains("segment 1 spans bytes 64..10000"), "{m}");
        let m = msg(&good, 7);
        assert!(m.contains("dose.dcm") && m.contains("7 expected"), "{m}");
    }
}
