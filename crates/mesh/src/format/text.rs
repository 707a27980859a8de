//! Allocation-free tokenizing and number parsing/formatting over byte buffers, shared by the
//! text formats.

use std::io::{self, Write};

/// ASCII whitespace inside a line (a newline ends a line and is handled separately).
#[inline]
pub(crate) fn is_blank(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

/// Lines of a byte buffer without their `\n`, numbered from `first_line`.
pub(crate) struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    pub(crate) fn new(bytes: &'a [u8], first_line: usize) -> Self {
        Self {
            bytes,
            pos: 0,
            line: first_line,
        }
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);

    #[inline]
    fn next(&mut self) -> Option<(usize, &'a [u8])> {
        let rest = self.bytes.get(self.pos..)?;
        if rest.is_empty() {
            return None;
        }
        let (line, advance) = match rest.iter().position(|&b| b == b'\n') {
            Some(n) => (&rest[..n], n + 1),
            None => (rest, rest.len()),
        };
        self.pos += advance;
        let no = self.line;
        self.line += 1;
        Some((no, line))
    }
}

/// Whitespace-separated words of one line.
#[derive(Clone)]
pub(crate) struct Words<'a> {
    s: &'a [u8],
}

impl<'a> Words<'a> {
    #[inline]
    pub(crate) fn new(s: &'a [u8]) -> Self {
        Self { s }
    }
}

impl<'a> Iterator for Words<'a> {
    type Item = &'a [u8];

    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let start = self.s.iter().position(|&b| !is_blank(b))?;
        let s = &self.s[start..];
        let end = s.iter().position(|&b| is_blank(b)).unwrap_or(s.len());
        let (word, rest) = s.split_at(end);
        self.s = rest;
        Some(word)
    }
}

/// A token for an error message: lossy UTF-8, shortened.
pub(crate) fn show(tok: &[u8]) -> String {
    const MAX: usize = 40;
    let s = String::from_utf8_lossy(&tok[..tok.len().min(MAX)]);
    if tok.len() > MAX {
        format!("{s}…")
    } else {
        s.into_owned()
    }
}

/// Parse a decimal floating-point token (Rust/C syntax: `1`, `-2.5`, `.5`, `1e-3`, `inf`,
/// `nan`, …), correctly rounded.
#[inline]
pub(crate) fn parse_f64(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

/// Parse a decimal floating-point token directly to the nearest `f32` (no double rounding).
#[inline]
pub(crate) fn parse_f32(tok: &[u8]) -> Option<f32> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

/// Parse an optionally signed decimal integer; `None` on any other character or overflow.
#[inline]
pub(crate) fn parse_i64(tok: &[u8]) -> Option<i64> {
    let (neg, digits) = match tok.first()? {
        b'-' => (true, &tok[1..]),
        b'+' => (false, &tok[1..]),
        _ => (false, tok),
    };
    if digits.is_empty() {
        return None;
    }
    let mut v: i64 = 0;
    if digits.len() <= 18 {
        // At most 18 digits cannot overflow: no checks in the common case.
        for &b in digits {
            let d = b.wrapping_sub(b'0');
            if d > 9 {
                return None;
            }
            v = v * 10 - i64::from(d);
        }
    } else {
        for &b in digits {
            let d = b.wrapping_sub(b'0');
            if d > 9 {
                return None;
            }
            v = v.checked_mul(10)?.checked_sub(i64::from(d))?;
        }
    }
    if neg { Some(v) } else { v.checked_neg() }
}

/// Write `sep` followed by the decimal digits of `v` (no formatting machinery: this runs
/// once per face corner).
#[inline]
pub(crate) fn write_uint<W: Write + ?Sized>(w: &mut W, sep: u8, mut v: u64) -> io::Result<()> {
    let mut buf = [0u8; 21];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    i -= 1;
    buf[i] = sep;
    w.write_all(&buf[i..])
}

/// Write `x` as the shortest decimal that parses back to exactly `x` (positional notation
/// for moderate magnitudes, exponent notation otherwise; `NaN`, `inf`, `-inf` for
/// non-finite values, `-0` keeps its sign).
#[inline]
pub(crate) fn write_f64<W: Write + ?Sized>(w: &mut W, x: f64) -> io::Result<()> {
    let a = x.abs();
    if a.is_finite() && a != 0.0 && !(1e-5..1e16).contains(&a) {
        write!(w, "{x:e}")
    } else {
        write!(w, "{x}")
    }
}

/// [`write_f64`] for `f32` values (shortest decimal identifying the `f32`).
#[inline]
pub(crate) fn write_f32<W: Write + ?Sized>(w: &mut W, x: f32) -> io::Result<()> {
    let a = x.abs();
    if a.is_finite() && a != 0.0 && !(1e-5..1e16).contains(&a) {
        write!(w, "{x:e}")
    } else {
        write!(w, "{x}")
    }
}

/// Write a position as three shortest-round-trip numbers separated by single spaces (no
/// line end).
pub(crate) fn write_xyz<W: Write + ?Sized>(w: &mut W, p: glam::DVec3) -> io::Result<()> {
    write_f64(w, p.x)?;
    w.write_all(b" ")?;
    write_f64(w, p.y)?;
    w.write_all(b" ")?;
    write_f64(w, p.z)
}

/// Write the vertex indices of a face, each preceded by a space and offset by `base` (1 for
/// OBJ's one-based indices), then a line end.
pub(crate) fn write_face_indices<W: Write + ?Sized>(
    w: &mut W,
    face: &[u32],
    base: u64,
) -> io::Result<()> {
    for &i in face {
        write_uint(w, b' ', u64::from(i) + base)?;
    }
    w.write_all(b"\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers() {
        assert_eq!(parse_i64(b"0"), Some(0));
        assert_eq!(parse_i64(b"-17"), Some(-17));
        assert_eq!(parse_i64(b"+5"), Some(5));
        assert_eq!(parse_i64(b"9223372036854775807"), Some(i64::MAX));
        assert_eq!(parse_i64(b"-9223372036854775808"), Some(i64::MIN));
        assert_eq!(parse_i64(b"9223372036854775808"), None);
        assert_eq!(parse_i64(b""), None);
        assert_eq!(parse_i64(b"-"), None);
        assert_eq!(parse_i64(b"1x"), None);
        assert_eq!(parse_i64(b"1.0"), None);
        assert_eq!(
            parse_i64(b"999999999999999999"),
            Some(999_999_999_999_999_999)
        );
        assert_eq!(parse_i64(b"-000000000000000000000042"), Some(-42));
    }

    #[test]
    fn floats_round_trip_shortest() {
        for x in [
            0.1,
            -0.0,
            1.0 / 3.0,
            1e300,
            -2.5e-300,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            123456.789,
            1e-5,
            1e16,
        ] {
            let mut s = Vec::new();
            write_f64(&mut s, x).unwrap();
            let y = parse_f64(&s).unwrap();
            assert_eq!(x.to_bits(), y.to_bits(), "{}", String::from_utf8_lossy(&s));
        }
        let mut s = Vec::new();
        write_f64(&mut s, 0.5).unwrap();
        assert_eq!(s, b"0.5");
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut s = Vec::new();
            write_f64(&mut s, x).unwrap();
            let y = parse_f64(&s).unwrap();
            assert!(x.is_nan() && y.is_nan() || x == y);
        }
        for x in [0.1f32, 1e-30, 3.4e38, -7.25] {
            let mut s = Vec::new();
            write_f32(&mut s, x).unwrap();
            assert_eq!(parse_f32(&s).unwrap().to_bits(), x.to_bits());
        }
    }

    #[test]
    fn unsigned_integers() {
        let mut s = Vec::new();
        for v in [0, 7, 10, 4_294_967_295, u64::MAX] {
            write_uint(&mut s, b' ', v).unwrap();
        }
        assert_eq!(s, b" 0 7 10 4294967295 18446744073709551615");
    }

    #[test]
    fn words_and_lines() {
        let words: Vec<_> = Words::new(b" f  1/2/3\t4//5 ").collect();
        assert_eq!(words, vec![&b"f"[..], b"1/2/3", b"4//5"]);
        let lines: Vec<_> = Lines::new(b"x\ny\n", 1).collect();
        assert_eq!(lines, vec![(1, &b"x"[..]), (2, &b"y"[..])]);
    }
}
