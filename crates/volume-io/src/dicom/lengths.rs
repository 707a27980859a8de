//! Refusing a DICOM stream whose elements declare more bytes than the stream holds, before
//! dicom-rs parses it.
//!
//! dicom-rs sizes a value's buffer from the element's declared length and only then reads
//! the value, so a forged length of a few GiB in a 1 KB file is allocated (and zeroed) before
//! the read fails. dicom-rs has no limit of its own, so volmorph checks first:
//!
//! * **The data set** is walked by dicom-rs's own token reader (`DataSetReader`, the one
//!   `dicom-object` builds objects with, with the same options), over a source that counts the
//!   bytes it has handed out. Every token that announces a length before its value is read
//!   (an element header, a sequence or item start, a pixel-data fragment) is checked against
//!   the bytes that remain at that point. The check therefore sees exactly the headers the
//!   parser will see, whatever quirks its reading has. Values, pixel data included, are read
//!   as the parser reads them and dropped at once: skipping a value by its declared length
//!   would not do, since the parser reads binary values as whole numbers only and leaves
//!   the rest of a misaligned length to be read as the next header.
//! * **The meta group** (0002,xxxx) is read by dicom-object's own meta reader, which has no
//!   token stream; [`check_meta`] walks it as that reader does (explicit VR little endian,
//!   ended by the (0002,0000) group length, unknown VRs read as UN).
//!
//! Deflated data sets are inflated once to learn their length (refused beyond the memory
//! budget) and then walked like any other, with lengths checked against the inflated bytes.

use std::cell::Cell;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::rc::Rc;

use dicom_core::Tag;
use dicom_encoding::{Codec, TransferSyntax, TransferSyntaxIndex};
use dicom_object::FileMetaTable;
use dicom_parser::dataset::{DataSetReader, DataToken};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use volmorph_volume::VolumeError;

use super::err;
use crate::text_header::{fill, os_err};

/// (7FE0,0010) Pixel Data.
const PIXEL_DATA: Tag = Tag(0x7FE0, 0x0010);

/// A reader that counts the bytes it has returned.
struct Counted<R> {
    inner: R,
    read: Rc<Cell<u64>>,
}

impl<R> Counted<R> {
    /// `inner`, counted, and the count.
    fn new(inner: R) -> (Self, Rc<Cell<u64>>) {
        let read = Rc::new(Cell::new(0));
        let counted = Self {
            inner,
            read: Rc::clone(&read),
        };
        (counted, read)
    }
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read.set(self.read.get() + n as u64);
        Ok(n)
    }
}

/// Refuse a DICOM stream (`src`, `total` bytes long, positioned anywhere) in which an element
/// declares a defined length longer than the bytes that remain where its value starts. The
/// stream is laid out as dicom-object reads it: `DICM` at 128 (after a preamble) or at 0, the
/// meta group, then the data set in the meta group's transfer syntax. With `until_pixel_data`
/// the walk ends at (7FE0,0010) in the root data set, as a header-only read does. A stream
/// the parser will refuse for another reason (no magic, a malformed header, an unknown
/// transfer syntax) passes: the parser reports it, having allocated nothing the check let
/// through. `what` names the stream in the error.
///
/// # Errors
/// [`VolumeError::Format`] naming the element, its declared length and the bytes that
/// remain; [`VolumeError::Io`] when a deflated data set inflates beyond the memory budget or
/// `src` cannot be read.
pub(super) fn check<R: Read + Seek>(
    mut src: R,
    total: u64,
    until_pixel_data: bool,
    what: &str,
) -> Result<(), VolumeError> {
    let io = os_err(Path::new(what));
    // The magic: dicom-object looks for it at 128 first, then at 0.
    let mut head = [0u8; 132];
    src.seek(SeekFrom::Start(0)).map_err(io)?;
    let n = fill(&mut src, &mut head).map_err(io)?;
    let magic: u64 = if n == 132 && &head[128..132] == b"DICM" {
        128
    } else if head.starts_with(b"DICM") {
        0
    } else {
        return Ok(()); // not DICOM: the parser refuses it
    };
    // The meta group, walked as dicom-object's meta reader will read it.
    check_meta(&mut src, magic + 4, total, what)?;
    // Let dicom-object's meta reader read it, counting the bytes it takes.
    src.seek(SeekFrom::Start(magic)).map_err(io)?;
    let (mut counted, read) = Counted::new(&mut src);
    let Ok(table) = FileMetaTable::from_reader(&mut counted) else {
        return Ok(()); // the parser refuses the meta group
    };
    let data_start = magic + read.get();
    let Some(ts) = TransferSyntaxRegistry.get(table.transfer_syntax()) else {
        return Ok(()); // the parser refuses an unknown transfer syntax
    };
    // The data set's bytes as the parser reads them, and how many there are.
    src.seek(SeekFrom::Start(data_start)).map_err(io)?;
    let (data, len): (Box<dyn Read + '_>, u64) = match ts.codec() {
        Codec::Dataset(None) => return Ok(()), // the parser refuses it (no adapter built in)
        Codec::Dataset(Some(adapter)) => {
            // Deflated: learn the inflated length, then walk the inflated stream.
            let limit = volmorph_io::memory_limit();
            let inflated = std::io::copy(
                &mut adapter
                    .adapt_reader(Box::new(&mut src))
                    .take(limit.saturating_add(1)),
                &mut std::io::sink(),
            );
            // A stream that does not inflate is the parser's to report.
            let Ok(inflated) = inflated else {
                return Ok(());
            };
            if inflated > limit {
                return Err(VolumeError::Io(volmorph_io::IoError::Budget {
                    what: format!("{what}: the inflated data set"),
                    bytes: inflated,
                    limit,
                }));
            }
            src.seek(SeekFrom::Start(data_start)).map_err(io)?;
            (adapter.adapt_reader(Box::new(&mut src)), inflated)
        }
        Codec::None | Codec::EncapsulatedPixelData(..) => (
            Box::new(std::io::BufReader::new(&mut src)),
            total - data_start,
        ),
    };
    let (source, read) = Counted::new(data);
    walk(source, ts, &read, len, until_pixel_data, what)
}

/// Walk a data set's tokens from `source` (`len` bytes long; `read` counts the bytes taken
/// from it), checking each announced length against the bytes left. Values are read as the
/// parser reads them (pixel data too: the parser reads a binary value as whole numbers only,
/// `len − len mod size` bytes, and where the next header starts depends on that).
fn walk<R: Read>(
    source: Counted<R>,
    ts: &TransferSyntax,
    read: &Cell<u64>,
    len: u64,
    until_pixel_data: bool,
    what: &str,
) -> Result<(), VolumeError> {
    let Ok(tokens) = DataSetReader::new_with_ts_options(source, ts, Default::default()) else {
        return Ok(());
    };
    let fits = |tag: Tag, declared: Option<u32>| -> Result<(), VolumeError> {
        let remain = len.saturating_sub(read.get());
        match declared {
            Some(n) if u64::from(n) > remain => Err(err(format!(
                "{what}: element ({:04X},{:04X}) declares {n} bytes, but only {remain} remain",
                tag.group(),
                tag.element()
            ))),
            _ => Ok(()),
        }
    };
    // The sequences entered and not yet left, innermost last (items are named after their
    // sequence in errors); none in the root data set.
    let mut seq_tags: Vec<Tag> = Vec::new();
    for token in tokens {
        // A malformed stream: the parser stops at the same token and reports it.
        let Ok(token) = token else {
            return Ok(());
        };
        match token {
            DataToken::ElementHeader(h) => {
                if seq_tags.is_empty() && h.tag == PIXEL_DATA && until_pixel_data {
                    return Ok(());
                }
                fits(h.tag, h.len.get())?;
            }
            DataToken::SequenceStart { tag, len } => {
                fits(tag, len.get())?;
                seq_tags.push(tag);
            }
            DataToken::PixelSequenceStart => {
                if seq_tags.is_empty() && until_pixel_data {
                    return Ok(());
                }
                seq_tags.push(PIXEL_DATA);
            }
            DataToken::ItemStart { len } => {
                let tag = seq_tags.last().copied().unwrap_or(Tag(0xFFFE, 0xE000));
                fits(tag, len.get())?;
            }
            DataToken::SequenceEnd => {
                seq_tags.pop();
            }
            _ => {}
        }
    }
    Ok(())
}

/// Walk the meta group of `src` (which starts at byte `start`, after `DICM`, of a `total`-byte
/// stream) as dicom-object's meta reader does, refusing a value longer than the bytes that
/// remain. The reader takes (0002,0000), a UL of 4 bytes holding the group length, then
/// explicit-VR little-endian elements of any group, each read whole, until that many bytes
/// are consumed. Only the headers are read; values are skipped.
///
/// # Errors
/// [`VolumeError::Format`] naming the element, its declared length and the bytes that
/// remain; [`VolumeError::Io`] when `src` cannot be read.
fn check_meta<R: Read + Seek>(
    src: &mut R,
    start: u64,
    total: u64,
    what: &str,
) -> Result<(), VolumeError> {
    // An explicit-VR header: tag, VR, then a 2-byte length, or 2 reserved bytes and a 4-byte
    // length. `None` where the stream ends (the reader reports that).
    let io = os_err(Path::new(what));
    let header = |src: &mut R, at: u64| -> Result<Option<MetaHeader>, VolumeError> {
        let mut b = [0u8; 12];
        src.seek(SeekFrom::Start(at)).map_err(io)?;
        let n = fill(&mut *src, &mut b).map_err(io)?;
        let tag = (
            u16::from_le_bytes([b[0], b[1]]),
            u16::from_le_bytes([b[2], b[3]]),
        );
        Ok(if n >= 12 && long_vr(&b[4..6]) {
            Some((tag, u32::from_le_bytes([b[8], b[9], b[10], b[11]]), at + 12))
        } else if n >= 8 && !long_vr(&b[4..6]) {
            Some((tag, u32::from(u16::from_le_bytes([b[6], b[7]])), at + 8))
        } else {
            None
        })
    };
    // (0002,0000) with a length of 4, whatever its VR: anything else is refused by the reader.
    let Some(((2, 0), 4, value_at)) = header(src, start)? else {
        return Ok(());
    };
    let mut b = [0u8; 4];
    src.seek(SeekFrom::Start(value_at)).map_err(io)?;
    if fill(&mut *src, &mut b).map_err(io)? < 4 {
        return Ok(());
    }
    let mut left = u64::from(u32::from_le_bytes(b));
    let mut pos = value_at + 4;
    while left > 0 {
        let Some(((group, elem), len, value_at)) = header(src, pos)? else {
            return Ok(());
        };
        if len == u32::MAX {
            return Ok(()); // undefined length in the meta group: the reader refuses it
        }
        let remain = total.saturating_sub(value_at);
        if u64::from(len) > remain {
            return Err(err(format!(
                "{what}: element ({group:04X},{elem:04X}) declares {len} bytes, but only {remain} remain"
            )));
        }
        left = left.saturating_sub(value_at - pos + u64::from(len));
        pos = value_at + u64::from(len);
    }
    Ok(())
}

/// An explicit-VR element header of the meta group: (group, element), value length, and
/// where the value starts.
type MetaHeader = ((u16, u16), u32, u64);

/// Whether an explicit VR carries 2 reserved bytes and a 4-byte length. PS3.5 7.1.2 lists the
/// VRs with a 2-byte length; every other VR, and (as dicom-rs reads it) an unrecognised VR,
/// which it takes for UN, has the long form.
fn long_vr(vr: &[u8]) -> bool {
    !matches!(
        vr,
        b"AE"
            | b"AS"
            | b"AT"
            | b"CS"
            | b"DA"
            | b"DS"
            | b"DT"
            | b"FL"
            | b"FD"
            | b"IS"
            | b"LO"
            | b"LT"
            | b"PN"
            | b"SH"
            | b"SL"
            | b"SS"
            | b"ST"
            | b"TM"
            | b"UI"
            | b"UL"
            | b"US"
    )
}
