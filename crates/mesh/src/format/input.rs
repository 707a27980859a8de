//! The input of the PLY, STL and OFF readers: a cursor over a window of the file that the
//! parsers see as contiguous bytes, so one parser serves both a byte slice (the window is the
//! whole slice, nothing is copied) and a stream (a plain file or a gzip file inflated while it
//! is read: the window is a buffer of [`CHUNK`] bytes refilled as the cursor moves).
//!
//! A stream's window holds the unread part of the current token, line or binary item and
//! nothing before it. Text lines and tokens longer than [`MAX_HELD`] are refused instead of
//! being buffered without bound (text after a comment marker does not count: it is skipped
//! as it is read, see [`Ignore`]); binary items are as long as the header declares them.
//!
//! Positions are absolute byte offsets from the start of the (decompressed) input, so error
//! messages are the same whichever way the file arrived. When the input's size is known (a
//! slice, an uncompressed file), [`Input::remaining`] gives it to the readers, which then
//! check declared counts against it before reading, and bound what they reserve by it;
//! otherwise they reserve a bounded amount and grow within the memory budget.

use std::io::{self, Read};

use super::text::is_blank;
use crate::error::Location;
use crate::{MeshError, MeshFormat};

/// Bytes read from a stream at a time (64 KiB).
pub(crate) const CHUNK: usize = 1 << 16;

/// Longest text line (comments excluded) or token held while reading a stream: 16 MiB, as
/// [`super::obj::MAX_STREAM_LINE`].
pub(crate) const MAX_HELD: usize = super::obj::MAX_STREAM_LINE;

/// Elements reserved up front for a declared count when the input's size is unknown; arrays
/// grow from there as data arrives.
const RESERVE_UNKNOWN: usize = 1 << 14;

/// What a refill of the window produced.
pub(crate) enum More {
    /// New bytes were appended.
    Got,
    /// The input has ended.
    Eof,
    /// The window already holds the limit asked for: nothing was read.
    Full,
}

/// Where the window's bytes come from.
pub(crate) trait Source {
    /// The window: the bytes available from the start of what is still held.
    fn data(&self) -> &[u8];
    /// Drop the first `consumed` bytes of the window and append more, unless the rest already
    /// holds `limit` bytes.
    fn more(&mut self, consumed: usize, limit: usize) -> io::Result<More>;
}

/// A byte slice: the window is the whole slice.
pub(crate) struct SliceSource<'a>(&'a [u8]);

impl Source for SliceSource<'_> {
    #[inline]
    fn data(&self) -> &[u8] {
        self.0
    }

    fn more(&mut self, consumed: usize, _limit: usize) -> io::Result<More> {
        self.0 = &self.0[consumed..];
        Ok(More::Eof)
    }
}

/// A reader, buffered here.
pub(crate) struct ReadSource<R> {
    r: R,
    buf: Vec<u8>,
    /// Bytes asked of the reader per refill.
    chunk: usize,
}

impl<R: Read> Source for ReadSource<R> {
    #[inline]
    fn data(&self) -> &[u8] {
        &self.buf
    }

    fn more(&mut self, consumed: usize, limit: usize) -> io::Result<More> {
        self.buf.drain(..consumed);
        let held = self.buf.len();
        if held >= limit {
            return Ok(More::Full);
        }
        let want = self.chunk;
        if self.buf.capacity() < held + want {
            // Double, but never past what the limit lets the window hold.
            let target = (2 * self.buf.capacity()).clamp(held + want, limit.max(held) + want);
            self.buf.reserve_exact(target - held);
        }
        self.buf.resize(held + want, 0);
        loop {
            match self.r.read(&mut self.buf[held..]) {
                Ok(n) => {
                    self.buf.truncate(held + n);
                    return Ok(if n == 0 { More::Eof } else { More::Got });
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.buf.truncate(held);
                    return Err(e);
                }
            }
        }
    }
}

/// What of a text line the caller ignores, so that a stream need not hold it.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Ignore {
    /// Everything from this byte on (`#` comments).
    From(u8),
    /// Everything after the first word when it is one of these (PLY `comment` lines).
    AfterWord(&'static [&'static [u8]]),
}

impl Ignore {
    /// Length of the wanted start of a line of which `line` is the beginning (`searched`
    /// bytes of it were looked at by an earlier call), when the rest can be dropped.
    fn cut(self, line: &[u8], searched: usize) -> Option<usize> {
        match self {
            Self::From(c) => line[searched..]
                .iter()
                .position(|&b| b == c)
                .map(|i| searched + i),
            Self::AfterWord(words) => {
                let start = line.iter().position(|&b| !is_blank(b))?;
                let len = line[start..].iter().position(|&b| is_blank(b))?;
                let end = start + len;
                words.contains(&&line[start..end]).then_some(end)
            }
        }
    }
}

/// A reader's cursor; see the module documentation.
pub(crate) struct Input<S> {
    src: S,
    /// Cursor within `src.data()`.
    pos: usize,
    /// Absolute offset of `src.data()[0]`.
    base: u64,
    /// The source has no more bytes than its window.
    eof: bool,
    /// Line of the cursor (1-based), as counted by the text methods.
    pub(crate) line: usize,
    /// Size of the whole input, when known.
    len: Option<u64>,
    format: MeshFormat,
    /// Names the input in I/O errors (a path).
    name: String,
    /// A line's wanted start when the rest of it was dropped while reading.
    scratch: Vec<u8>,
}

impl<'a> Input<SliceSource<'a>> {
    /// The whole of `bytes`, in `format`.
    pub(crate) fn slice(bytes: &'a [u8], format: MeshFormat) -> Self {
        Self::new(
            SliceSource(bytes),
            true,
            Some(bytes.len() as u64),
            format,
            String::new(),
        )
    }
}

impl<R: Read> Input<ReadSource<R>> {
    /// A stream of `len` bytes if known, named `name` in I/O errors.
    pub(crate) fn reader(r: R, len: Option<u64>, format: MeshFormat, name: String) -> Self {
        Self::reader_with_chunk(r, len, format, name, CHUNK)
    }

    /// [`Input::reader`] asking the reader for `chunk` bytes at a time (tests use tiny ones).
    pub(crate) fn reader_with_chunk(
        r: R,
        len: Option<u64>,
        format: MeshFormat,
        name: String,
        chunk: usize,
    ) -> Self {
        let src = ReadSource {
            r,
            buf: Vec::new(),
            chunk: chunk.max(1),
        };
        Self::new(src, false, len, format, name)
    }
}

impl<S: Source> Input<S> {
    fn new(src: S, eof: bool, len: Option<u64>, format: MeshFormat, name: String) -> Self {
        Self {
            src,
            pos: 0,
            base: 0,
            eof,
            line: 1,
            len,
            format,
            name,
            scratch: Vec::new(),
        }
    }

    /// Absolute offset of the cursor.
    #[inline]
    pub(crate) fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    /// Bytes after the cursor, when the input's size is known.
    pub(crate) fn remaining(&self) -> Option<u64> {
        self.len.map(|l| l.saturating_sub(self.offset()))
    }

    /// Size of the input once it has ended (the offset of its end).
    pub(crate) fn end(&self) -> u64 {
        self.base + self.src.data().len() as u64
    }

    /// How many of `count` declared items of at least `min_bytes` bytes each to reserve room
    /// for: as many as the rest of the input can hold when its size is known, a bounded
    /// number otherwise.
    pub(crate) fn capacity_hint(&self, count: usize, min_bytes: usize) -> usize {
        match self.remaining() {
            Some(r) => {
                count.min(usize::try_from(r / min_bytes.max(1) as u64).unwrap_or(usize::MAX))
            }
            None => count.min(RESERVE_UNKNOWN),
        }
    }

    fn io_error(&self, error: io::Error) -> MeshError {
        MeshError::Io(volmorph_io::IoError::Os {
            path: self.name.clone(),
            error,
        })
    }

    /// Drop the window before `keep` and read more, holding at most `limit` bytes (`what`
    /// names the text held, for the error beyond that). `false` at the end of the input.
    #[cold]
    fn refill(&mut self, keep: usize, limit: usize, what: &str) -> Result<bool, MeshError> {
        if self.eof {
            return Ok(false);
        }
        let r = self.src.more(keep, limit);
        self.base += keep as u64;
        self.pos -= keep;
        match r {
            Ok(More::Got) => Ok(true),
            Ok(More::Eof) => {
                self.eof = true;
                Ok(false)
            }
            Ok(More::Full) => Err(MeshError::parse(
                self.format,
                Location::Line(self.line),
                format!("{what} is longer than {limit} bytes"),
            )),
            Err(e) => Err(self.io_error(e)),
        }
    }

    // ------------------------------------------------------------------ binary

    /// Make `n` bytes after the cursor available; `false` if the input ends first.
    #[inline]
    pub(crate) fn ensure(&mut self, n: usize) -> Result<bool, MeshError> {
        if self.src.data().len() - self.pos >= n {
            return Ok(true);
        }
        self.ensure_slow(n)
    }

    #[cold]
    fn ensure_slow(&mut self, n: usize) -> Result<bool, MeshError> {
        while self.src.data().len() - self.pos < n {
            if !self.refill(self.pos, n.max(MAX_HELD), "a binary item")? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// The next `n` bytes, moving past them; `None` (not moving) if the input ends first.
    #[inline]
    pub(crate) fn take(&mut self, n: usize) -> Result<Option<&[u8]>, MeshError> {
        if !self.ensure(n)? {
            return Ok(None);
        }
        let s = self.pos;
        self.pos += n;
        Ok(Some(&self.src.data()[s..s + n]))
    }

    /// Up to `n` bytes after the cursor (fewer only at the end of the input), not moving.
    pub(crate) fn peek(&mut self, n: usize) -> Result<&[u8], MeshError> {
        self.ensure(n)?;
        let d = &self.src.data()[self.pos..];
        Ok(&d[..n.min(d.len())])
    }

    /// The bytes after the cursor that the window holds (possibly none).
    #[inline]
    pub(crate) fn window(&self) -> &[u8] {
        &self.src.data()[self.pos..]
    }

    /// Move past `n` bytes of [`Input::window`].
    #[inline]
    pub(crate) fn advance(&mut self, n: usize) {
        debug_assert!(n <= self.window().len());
        self.pos += n;
    }

    /// Move past up to `n` bytes; returns how many there were.
    pub(crate) fn skip(&mut self, n: u64) -> Result<u64, MeshError> {
        let mut left = n;
        loop {
            let k = (self.window().len() as u64).min(left);
            self.pos += k as usize;
            left -= k;
            if left == 0 || !self.refill(self.pos, MAX_HELD, "skipped data")? {
                return Ok(n - left);
            }
        }
    }

    // ------------------------------------------------------------------ text

    /// The next whitespace-separated token and its line, or `None` at the end of the input.
    #[inline(always)]
    pub(crate) fn next_token(&mut self) -> Result<Option<(usize, &[u8])>, MeshError> {
        Ok(self
            .token_range()?
            .map(|(s, e)| (self.line, &self.src.data()[s..e])))
    }

    /// The next token and its line; at the end of the input, the error `missing` makes of
    /// the line there.
    #[inline(always)]
    pub(crate) fn require_token(
        &mut self,
        missing: impl FnOnce(usize) -> MeshError,
    ) -> Result<(usize, &[u8]), MeshError> {
        match self.token_range()? {
            Some((s, e)) => Ok((self.line, &self.src.data()[s..e])),
            None => Err(missing(self.line)),
        }
    }

    /// Where in the window the next token is, the cursor moved past it: here when the window
    /// holds it whole, else by [`Input::token_range_slow`].
    #[inline(always)]
    fn token_range(&mut self) -> Result<Option<(usize, usize)>, MeshError> {
        let d = self.src.data();
        let mut p = self.pos;
        // Bytes above the space are word bytes: one comparison for most bytes.
        while let Some(&b) = d.get(p) {
            if b > b' ' {
                break;
            } else if b == b'\n' {
                self.line += 1;
            } else if !is_blank(b) {
                break;
            }
            p += 1;
        }
        self.pos = p;
        if p < d.len() {
            let mut e = p + 1;
            while let Some(&b) = d.get(e) {
                if b <= b' ' && (b == b'\n' || is_blank(b)) {
                    break;
                }
                e += 1;
            }
            if e < d.len() || self.eof {
                self.pos = e;
                return Ok(Some((p, e)));
            }
        }
        self.token_range_slow()
    }

    /// [`Input::token_range`] where the window ends before the token does, or before one
    /// starts.
    #[cold]
    #[inline(never)]
    fn token_range_slow(&mut self) -> Result<Option<(usize, usize)>, MeshError> {
        let (start, end) = loop {
            let d = self.src.data();
            let mut p = self.pos;
            while let Some(&b) = d.get(p) {
                if b == b'\n' {
                    self.line += 1;
                } else if !is_blank(b) {
                    break;
                }
                p += 1;
            }
            self.pos = p;
            if p == d.len() {
                if !self.refill(p, MAX_HELD, "a word")? {
                    return Ok(None);
                }
                continue;
            }
            let mut e = p + 1;
            while let Some(&b) = d.get(e) {
                if b == b'\n' || is_blank(b) {
                    break;
                }
                e += 1;
            }
            if e < d.len() || self.eof {
                break (p, e);
            }
            // The token may go on past the window.
            if !self.refill(p, MAX_HELD, "a word")? {
                break (self.pos, self.src.data().len());
            }
        };
        self.pos = end;
        Ok(Some((start, end)))
    }

    /// Move past the next line break (or to the end of the input), without holding the line.
    /// `true` if there was a line break.
    fn skip_past_newline(&mut self) -> Result<bool, MeshError> {
        loop {
            if let Some(i) = self.window().iter().position(|&b| b == b'\n') {
                self.pos += i + 1;
                return Ok(true);
            }
            self.pos = self.src.data().len();
            if !self.refill(self.pos, MAX_HELD, "a line")? {
                return Ok(false);
            }
        }
    }

    /// Skip the rest of the current line, including its line break.
    pub(crate) fn skip_line(&mut self) -> Result<(), MeshError> {
        if self.skip_past_newline()? {
            self.line += 1;
        }
        Ok(())
    }

    /// The next line without its `\n`, or `None` at the end of the input: its number, where
    /// its wanted bytes are (see [`Ignore`]; what is ignored may or may not be included; read
    /// them with [`Input::line_bytes`] before moving on) and whether it ended with a line
    /// break.
    #[inline(always)]
    pub(crate) fn read_line(&mut self, ignore: Ignore) -> Result<Option<Line>, MeshError> {
        let d = self.src.data();
        let start = self.pos;
        if let Some(i) = d[start..].iter().position(|&b| b == b'\n') {
            let no = self.line;
            self.line += 1;
            self.pos = start + i + 1;
            return Ok(Some(Line {
                no,
                start,
                end: start + i,
                in_scratch: false,
                newline: true,
            }));
        }
        self.read_line_slow(ignore)
    }

    /// [`Input::read_line`] where the window does not hold the rest of the line.
    #[cold]
    #[inline(never)]
    fn read_line_slow(&mut self, ignore: Ignore) -> Result<Option<Line>, MeshError> {
        let no = self.line;
        // Bytes of the line already searched for the line break and for `ignore`.
        let mut searched = 0usize;
        let line = loop {
            let d = self.src.data();
            let start = self.pos;
            if let Some(i) = d[start + searched..].iter().position(|&b| b == b'\n') {
                let end = start + searched + i;
                self.pos = end + 1;
                break Line {
                    no,
                    start,
                    end,
                    in_scratch: false,
                    newline: true,
                };
            }
            if self.eof {
                if d.len() == start {
                    return Ok(None);
                }
                self.pos = d.len();
                break Line {
                    no,
                    start,
                    end: d.len(),
                    in_scratch: false,
                    newline: false,
                };
            }
            if let Some(cut) = ignore.cut(&d[start..], searched) {
                // The rest of the line is not wanted: keep its start, drop the rest unread.
                self.scratch.clear();
                self.scratch.extend_from_slice(&d[start..start + cut]);
                self.pos = d.len();
                let newline = self.skip_past_newline()?;
                break Line {
                    no,
                    start: 0,
                    end: cut,
                    in_scratch: true,
                    newline,
                };
            }
            searched = d.len() - start;
            self.refill(start, MAX_HELD, "a line")?;
        };
        self.line += 1;
        Ok(Some(line))
    }

    /// The bytes of `line`, the line [`Input::read_line`] returned last.
    #[inline(always)]
    pub(crate) fn line_bytes(&self, line: &Line) -> &[u8] {
        if line.in_scratch {
            &self.scratch[line.start..line.end]
        } else {
            &self.src.data()[line.start..line.end]
        }
    }
}

/// A line found by [`Input::read_line`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line {
    /// Its 1-based number.
    pub(crate) no: usize,
    start: usize,
    end: usize,
    in_scratch: bool,
    /// It ended with a line break (not with the end of the input).
    pub(crate) newline: bool,
}

/// A byte offset as an error location.
pub(crate) fn at_byte(offset: u64) -> Location {
    Location::Byte(usize::try_from(offset).unwrap_or(usize::MAX))
}

/// Reserve room for `n` more elements of `v`, no more than the memory budget allows
/// (growth beyond that is checked as elements are pushed), and nothing if the allocator
/// refuses.
pub(crate) fn reserve_within<T>(v: &mut Vec<T>, n: usize) {
    let size = std::mem::size_of::<T>().max(1) as u64;
    let fit = usize::try_from(volmorph_io::memory_limit() / size).unwrap_or(usize::MAX);
    let _ = v.try_reserve_exact(n.min(fit));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs(bytes: &[u8]) -> Vec<Input<ReadSource<&[u8]>>> {
        [1, 2, 3, 7, CHUNK]
            .into_iter()
            .map(|c| Input::reader_with_chunk(bytes, None, MeshFormat::Off, "t".into(), c))
            .collect()
    }

    #[test]
    fn tokens_and_lines_across_refills() {
        let text = b"ab  c\n\n d\r\ne # x y\nlast";
        let mut s = Input::slice(text, MeshFormat::Off);
        let mut want = Vec::new();
        while let Some((l, t)) = s.next_token().unwrap() {
            want.push((l, t.to_vec()));
        }
        let words: Vec<&[u8]> = vec![b"ab", b"c", b"d", b"e", b"#", b"x", b"y", b"last"];
        let lines = [1, 1, 3, 4, 4, 4, 4, 5];
        assert_eq!(
            want,
            lines
                .into_iter()
                .zip(words)
                .map(|(l, w)| (l, w.to_vec()))
                .collect::<Vec<_>>()
        );
        for mut i in inputs(text) {
            let mut got = Vec::new();
            while let Some((l, t)) = i.next_token().unwrap() {
                got.push((l, t.to_vec()));
            }
            assert_eq!(got, want);
        }
        for mut i in inputs(text) {
            let mut lines = Vec::new();
            while let Some(line) = i.read_line(Ignore::From(b'#')).unwrap() {
                let (n, l, nl) = (line.no, i.line_bytes(&line), line.newline);
                let l = match l.iter().position(|&b| b == b'#') {
                    Some(h) => &l[..h],
                    None => l,
                };
                lines.push((n, l.to_vec(), nl));
            }
            assert_eq!(lines[2], (3, b" d\r".to_vec(), true));
            assert_eq!(lines[3], (4, b"e ".to_vec(), true));
            assert_eq!(lines[4], (5, b"last".to_vec(), false));
            assert_eq!(lines.len(), 5);
        }
    }

    #[test]
    fn binary_takes_and_skips_across_refills() {
        let bytes: Vec<u8> = (0..=255).collect();
        for mut i in inputs(&bytes) {
            assert_eq!(i.take(3).unwrap().unwrap(), &[0, 1, 2]);
            assert_eq!(i.skip(100).unwrap(), 100);
            assert_eq!(i.offset(), 103);
            assert_eq!(i.peek(2).unwrap(), &[103, 104]);
            assert_eq!(i.take(150).unwrap().unwrap()[149], 252);
            assert!(i.take(4).unwrap().is_none());
            assert_eq!(i.skip(10).unwrap(), 3);
            assert_eq!(i.end(), 256);
        }
    }
}
