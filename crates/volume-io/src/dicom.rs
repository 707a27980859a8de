//! DICOM image series (a folder of CT/MR/PET slices) and multi-frame (enhanced) DICOM files,
//! read into one 3-D volume in patient (LPS) space.
//!
//! Parsing and pixel decoding are done by the `dicom-rs` crates (`dicom-object`,
//! `dicom-pixeldata`; the decoders of compressed transfer syntaxes — JPEG, JPEG lossless,
//! RLE, deflate — come with the default `dicom-codecs` feature; RLE of 32-bit samples, which
//! that decoder does not read, is decoded here, in the private `rle` module). This module does what turns
//! files into a volume:
//!
//! # Finding the slices
//!
//! * A **folder**: every file in it (not its subfolders) that parses as DICOM and carries image
//!   pixels is grouped by `SeriesInstanceUID`; one series is read, several are an error listing
//!   each series (UID, description, slice count) — read one by naming any of its files.
//! * A **file** with one frame: the series it belongs to, from the files of its folder.
//! * A **multi-frame** file (`NumberOfFrames` > 1): its frames are the slices. Each frame's
//!   position, orientation, pixel spacing and rescale come from the enhanced functional groups
//!   (`PerFrameFunctionalGroupsSequence`, falling back to `SharedFunctionalGroupsSequence`:
//!   `PlanePositionSequence`, `PlaneOrientationSequence`, `PixelMeasuresSequence`,
//!   `PixelValueTransformationSequence`), or, in classic multi-frame files, from the top-level
//!   `ImagePositionPatient`/`ImageOrientationPatient` with frames stepped by
//!   `SpacingBetweenSlices` (or `SliceThickness`) along the slice normal.
//!
//! # Geometry
//!
//! `ImageOrientationPatient` gives the directions of increasing column (`i`) and row (`j`)
//! index; their cross product is the slice normal `n`. Slices are sorted by `n ·
//! ImagePositionPatient`, and checked: every slice has the same size, orientation (within
//! [`ORIENTATION_TOL`]) and pixel spacing; no two slices share a position (several
//! acquisitions, echoes or time points in one series are reported, not interleaved); and the
//! gaps between consecutive slices are equal within [`SLICE_GAP_TOL`] of their mean (a missing
//! slice is an error naming where it is missing). The volume's origin is the first slice's
//! position, the third direction column and spacing come from the first to the last position:
//! `(p_last − p_first) / (N − 1)`. That is the slice normal for ordinary series and the true
//! sheared axis for a tilted-gantry CT (whose direction is then not orthonormal, as the grid
//! is). Spacing along `i` and `j` is `PixelSpacing[1]` and `PixelSpacing[0]` (DICOM lists row
//! spacing first). A single slice gets `SpacingBetweenSlices`, else `SliceThickness`, else 1.
//!
//! # Values
//!
//! Stored values (`BitsAllocated` 1 — uncompressed, as segmentation masks store them — 8, 16
//! or 32; `PixelRepresentation` unsigned or two's
//! complement; the bits above `BitsStored` masked off, or sign-extended from `BitsStored` for
//! signed data) are mapped by each slice's `RescaleSlope`/`RescaleIntercept` (`v·slope +
//! intercept`). When every slice has slope 1 and the same integral intercept, the volume keeps
//! an integer type — the narrowest of u8, i8, u16, i16, u32, i32 that holds every value the
//! stored bits and the intercept can give (so CT with intercept −1024 is `i16` Hounsfield
//! units, as in ITK); otherwise it is `f32`. Only one sample per pixel
//! (`MONOCHROME1`/`MONOCHROME2`) is read; colour images are refused. Sizes are checked with
//! [`volmorph_io::checked_len`] before the volume is allocated.
//!
//! Writing DICOM is not supported (a DICOM file needs patient and study identity that a volume
//! does not carry): write NIfTI, NRRD, MetaImage or `.vti`.

use std::borrow::Borrow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dicom_core::VR;
use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
use dicom_core::header::Header as _;
use dicom_dictionary_std::{StandardDataDictionary, tags};
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions};
use dicom_pixeldata::PixelDecoder;
use glam::{DMat3, DVec3};

use crate::Header;
use volmorph_volume::{AnyVolume, Geometry, Volume, VolumeError, Voxel, VoxelType};

mod lengths;
mod rle;

const FMT: &str = "DICOM";

/// Largest difference between the orientation vectors of two slices of one series (they are
/// unit vectors printed as decimal strings, usually to 6 or more digits).
pub const ORIENTATION_TOL: f64 = 1e-4;

/// Largest deviation of a gap between consecutive slices from the mean gap, as a fraction of
/// it. Positions are decimal strings of at most 16 characters, rounded by scanners to about
/// 1e-3 mm, far below 1 % of any slice step; a missing slice doubles a gap (100 %).
pub const SLICE_GAP_TOL: f64 = 0.01;

/// Two slices closer than this along the normal (millimetres) are at the same position.
const SAME_POSITION_TOL: f64 = 1e-4;

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

/// Values of a numeric attribute of `obj`, if present and parsable.
fn floats(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<Vec<f64>> {
    obj.get(tag)?.to_multi_float64().ok()
}

fn float(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<f64> {
    floats(obj, tag)?.first().copied()
}

fn int(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<i64> {
    obj.get(tag)?.to_int::<i64>().ok()
}

fn text(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<String> {
    let s = obj.get(tag)?.to_str().ok()?;
    let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    (!s.is_empty()).then(|| s.to_owned())
}

/// Give the top-level attributes of `obj` stored with VR `UN` ("unknown": what a file
/// converted from implicit to explicit VR without a dictionary keeps, e.g. pydicom's
/// `explicit_VR-UN.dcm`) the VR the standard dictionary has for their tag, decoding their
/// bytes as that VR does: backslash-separated text for the string VRs, little-endian binary
/// for `US`, `SS`, `UL`, `SL`, `FL`, `FD` (`UN` values keep the little-endian encoding they were
/// read from, PS3.5 §6.2.2). Attributes with other VRs or unknown tags stay `UN`. Done once
/// after opening, so every later look-up (and the pixel decoder's own) sees typed values.
fn retype_un(obj: &mut InMemDicomObject) {
    use dicom_core::{DataElement, PrimitiveValue};
    let un: Vec<(dicom_object::Tag, Vec<u8>)> = obj
        .iter()
        .filter(|e| e.vr() == VR::UN)
        .filter_map(|e| Some((e.tag(), e.to_bytes().ok()?.into_owned())))
        .collect();
    fn binary<const N: usize, T>(b: &[u8], f: impl Fn([u8; N]) -> T) -> Option<Vec<T>> {
        b.len().is_multiple_of(N).then(|| {
            b.chunks_exact(N)
                .map(|c| f(c.try_into().unwrap_or([0; N])))
                .collect()
        })
    }
    for (tag, bytes) in un {
        let Some(vr) = StandardDataDictionary.by_tag(tag).map(|e| e.vr().relaxed()) else {
            continue;
        };
        let value =
            match vr {
                VR::AE
                | VR::AS
                | VR::CS
                | VR::DA
                | VR::DS
                | VR::DT
                | VR::IS
                | VR::LO
                | VR::LT
                | VR::PN
                | VR::SH
                | VR::ST
                | VR::TM
                | VR::UC
                | VR::UI
                | VR::UR
                | VR::UT => {
                    let t = String::from_utf8_lossy(&bytes);
                    let t = t.trim_end_matches(['\0', ' ']);
                    Some(PrimitiveValue::Strs(
                        t.split('\\').map(str::to_owned).collect(),
                    ))
                }
                VR::US => binary::<2, _>(&bytes, u16::from_le_bytes)
                    .map(|v| PrimitiveValue::U16(v.into())),
                VR::SS => binary::<2, _>(&bytes, i16::from_le_bytes)
                    .map(|v| PrimitiveValue::I16(v.into())),
                VR::UL => binary::<4, _>(&bytes, u32::from_le_bytes)
                    .map(|v| PrimitiveValue::U32(v.into())),
                VR::SL => binary::<4, _>(&bytes, i32::from_le_bytes)
                    .map(|v| PrimitiveValue::I32(v.into())),
                VR::FL => binary::<4, _>(&bytes, f32::from_le_bytes)
                    .map(|v| PrimitiveValue::F32(v.into())),
                VR::FD => binary::<8, _>(&bytes, f64::from_le_bytes)
                    .map(|v| PrimitiveValue::F64(v.into())),
                _ => None,
            }
            .unwrap_or(PrimitiveValue::Empty);
        if value != PrimitiveValue::Empty {
            obj.put(DataElement::new(tag, vr, value));
        }
    }
}

/// The first item of sequence `seq` in `obj`.
fn item(obj: &InMemDicomObject, seq: dicom_object::Tag) -> Option<&InMemDicomObject> {
    obj.get(seq)?.items()?.first()
}

/// Pixel-level description shared by every slice of a volume.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PixelFormat {
    rows: usize,
    cols: usize,
    bits_allocated: u16,
    bits_stored: u16,
    signed: bool,
}

impl PixelFormat {
    fn of(obj: &InMemDicomObject, what: &str) -> Result<Self, VolumeError> {
        let need = |tag, name: &str| int(obj, tag).ok_or_else(|| err(format!("{what}: no {name}")));
        let spp = int(obj, tags::SAMPLES_PER_PIXEL).unwrap_or(1);
        if spp != 1 {
            let pi = text(obj, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default();
            return Err(VolumeError::Unsupported(format!(
                "{what}: {spp} samples per pixel ({pi}); only greyscale images are volumes"
            )));
        }
        let rows = need(tags::ROWS, "Rows")?;
        let cols = need(tags::COLUMNS, "Columns")?;
        let bits_allocated = need(tags::BITS_ALLOCATED, "BitsAllocated")?;
        let bits_stored = int(obj, tags::BITS_STORED).unwrap_or(bits_allocated);
        let signed = int(obj, tags::PIXEL_REPRESENTATION).unwrap_or(0) == 1;
        if rows <= 0 || cols <= 0 {
            return Err(err(format!("{what}: Rows {rows} × Columns {cols}")));
        }
        if !matches!(bits_allocated, 1 | 8 | 16 | 32) {
            return Err(VolumeError::Unsupported(format!(
                "{what}: BitsAllocated {bits_allocated} (1, 8, 16 or 32 are read)"
            )));
        }
        if !(1..=bits_allocated).contains(&bits_stored) {
            return Err(err(format!(
                "{what}: BitsStored {bits_stored} with BitsAllocated {bits_allocated}"
            )));
        }
        Ok(Self {
            rows: rows as usize,
            cols: cols as usize,
            bits_allocated: bits_allocated as u16,
            bits_stored: bits_stored as u16,
            signed,
        })
    }

    /// Range of the stored values.
    fn range(&self) -> (f64, f64) {
        let b = i32::from(self.bits_stored);
        if self.signed {
            (-(2f64.powi(b - 1)), 2f64.powi(b - 1) - 1.0)
        } else {
            (0.0, 2f64.powi(b) - 1.0)
        }
    }

    /// Bytes of one decoded frame: `rows · cols · BitsAllocated / 8` (saturating); for
    /// 1-bit pixels one byte per pixel, as [`Pixels::frame`] unpacks them.
    fn frame_bytes(&self) -> usize {
        self.rows
            .saturating_mul(self.cols)
            .saturating_mul(usize::from(self.bits_allocated.div_ceil(8)))
    }

    /// Bytes of native (uncompressed) `PixelData` holding `frames` frames: 1-bit frames
    /// follow each other bit by bit (PS3.5 8.1.1), others byte-aligned.
    fn native_bytes(&self, frames: u32) -> u64 {
        let pixels = (self.rows as u64)
            .saturating_mul(self.cols as u64)
            .saturating_mul(u64::from(frames));
        if self.bits_allocated == 1 {
            pixels.div_ceil(8)
        } else {
            pixels.saturating_mul(u64::from(self.bits_allocated / 8))
        }
    }

    /// Stored value `k` of a frame's little-endian bytes, masked / sign-extended to
    /// `BitsStored`.
    #[inline]
    fn value(&self, bytes: &[u8], k: usize) -> i64 {
        let raw: u64 = match self.bits_allocated {
            // 1-bit pixels arrive unpacked, one byte each.
            1 | 8 => u64::from(bytes[k]),
            16 => u64::from(u16::from_le_bytes([bytes[2 * k], bytes[2 * k + 1]])),
            _ => u64::from(u32::from_le_bytes([
                bytes[4 * k],
                bytes[4 * k + 1],
                bytes[4 * k + 2],
                bytes[4 * k + 3],
            ])),
        };
        let bits = u32::from(self.bits_stored);
        let masked = raw & ((1u64 << bits) - 1);
        if self.signed && masked >> (bits - 1) == 1 {
            masked as i64 - (1i64 << bits)
        } else {
            masked as i64
        }
    }
}

/// One slice: where it is and where its pixels are.
#[derive(Debug, Clone)]
struct Plane {
    position: DVec3,
    /// Direction of increasing column index (`i`).
    row_dir: DVec3,
    /// Direction of increasing row index (`j`).
    col_dir: DVec3,
    /// Spacing along `i` and `j`.
    spacing: [f64; 2],
    slope: f64,
    intercept: f64,
    /// Index of the file in the list, and frame in that file.
    file: usize,
    frame: u32,
}

/// The geometry fields of a plane from `IOP`, `IPP` and `PixelSpacing` values.
fn plane_from(
    what: &str,
    iop: Option<Vec<f64>>,
    ipp: Option<Vec<f64>>,
    spacing: Option<Vec<f64>>,
) -> Result<(DVec3, DVec3, DVec3, [f64; 2]), VolumeError> {
    let iop = iop.filter(|v| v.len() == 6).ok_or_else(|| {
        err(format!(
            "{what}: no ImageOrientationPatient (6 numbers): not a slice in patient space"
        ))
    })?;
    let ipp = ipp
        .filter(|v| v.len() == 3)
        .ok_or_else(|| err(format!("{what}: no ImagePositionPatient (3 numbers)")))?;
    let r = DVec3::new(iop[0], iop[1], iop[2]);
    let c = DVec3::new(iop[3], iop[4], iop[5]);
    let (rn, cn) = (r.length(), c.length());
    if !(rn.is_finite() && cn.is_finite() && rn > 0.5 && cn > 0.5) {
        return Err(err(format!(
            "{what}: ImageOrientationPatient {iop:?} does not hold two unit vectors"
        )));
    }
    let p = DVec3::new(ipp[0], ipp[1], ipp[2]);
    if !p.is_finite() {
        return Err(err(format!(
            "{what}: ImagePositionPatient {ipp:?} is not finite"
        )));
    }
    let s = match spacing {
        Some(s) if s.len() == 2 => {
            if !(s[0] > 0.0 && s[1] > 0.0 && s[0].is_finite() && s[1].is_finite()) {
                return Err(err(format!("{what}: PixelSpacing {s:?} must be positive")));
            }
            [s[1], s[0]]
        }
        Some(s) => return Err(err(format!("{what}: PixelSpacing {s:?} needs 2 numbers"))),
        None => [1.0, 1.0],
    };
    Ok((p, r / rn, c / cn, s))
}

/// Header summary of one file, read without its pixel data.
struct Scanned {
    path: PathBuf,
    series: String,
    description: String,
    /// Read as a multi-frame file ([`is_multiframe`]).
    multiframe: bool,
}

/// Whether `obj` is read as a multi-frame file: more than one frame, or an enhanced file
/// (segmentations, enhanced CT/MR) whose one frame is placed by the functional groups
/// rather than by top-level `ImageOrientationPatient`.
fn is_multiframe(obj: &InMemDicomObject) -> bool {
    int(obj, tags::NUMBER_OF_FRAMES).unwrap_or(1) > 1
        || (obj.element(tags::IMAGE_ORIENTATION_PATIENT).is_err()
            && (obj
                .element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
                .is_ok()
                || obj.element(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE).is_ok()))
}

/// [`lengths::check`] on the bytes of a DICOM stream held in memory.
fn check_declared_lengths(
    bytes: &[u8],
    until_pixel_data: bool,
    what: &str,
) -> Result<(), VolumeError> {
    lengths::check(
        std::io::Cursor::new(bytes),
        bytes.len() as u64,
        until_pixel_data,
        what,
    )
}

/// [`lengths::check`] on a DICOM file.
fn check_declared_lengths_of_file(path: &Path, until_pixel_data: bool) -> Result<(), VolumeError> {
    let os = crate::text_header::os_err(path);
    let file = std::fs::File::open(path).map_err(os)?;
    let total = file.metadata().map_err(os)?.len();
    lengths::check(file, total, until_pixel_data, &path.display().to_string())
}

fn open_header(path: &Path) -> Option<DefaultDicomObject> {
    check_declared_lengths_of_file(path, true).ok()?;
    let mut obj = OpenFileOptions::new()
        .read_until(tags::PIXEL_DATA)
        .open_file(path)
        .ok()?;
    retype_un(&mut obj);
    Some(obj)
}

fn open_full(path: &Path) -> Result<DefaultDicomObject, VolumeError> {
    check_declared_lengths_of_file(path, false)?;
    let mut obj = OpenFileOptions::new()
        .open_file(path)
        .map_err(|e| err(format!("{}: {e}", path.display())))?;
    retype_un(&mut obj);
    Ok(obj)
}

fn scan(path: &Path) -> Option<Scanned> {
    let obj = open_header(path)?;
    // Images only: a pixel matrix is described.
    int(&obj, tags::ROWS)?;
    Some(Scanned {
        path: path.to_path_buf(),
        series: text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        description: text(&obj, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        multiframe: is_multiframe(&obj),
    })
}

fn scan_folder(dir: &Path) -> Result<Vec<Scanned>, VolumeError> {
    let os = crate::text_header::os_err(dir);
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(os)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    paths.sort();
    Ok(paths.iter().filter_map(|p| scan(p)).collect())
}

/// `true` if `path` is a file with the DICOM preamble magic `DICM` at byte 128.
pub(crate) fn has_dicom_magic(path: &Path) -> bool {
    use std::io::Read;
    let mut b = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut b))
        .is_ok()
        && &b[128..] == b"DICM"
}

/// Read a DICOM series (a folder, or any one file of it) or a multi-frame file.
pub(crate) fn read(path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    let (files, chosen_series) = if path.is_dir() {
        let files = scan_folder(path)?;
        if files.is_empty() {
            return Err(err(format!(
                "folder {} holds no DICOM image files",
                path.display()
            )));
        }
        (files, None)
    } else {
        let me = scan(path)
            .ok_or_else(|| err(format!("{} is not a DICOM image file", path.display())))?;
        if me.multiframe {
            return read_multiframe(path);
        }
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
        let files = match dir {
            Some(d) => scan_folder(d)?,
            None => scan_folder(Path::new("."))?,
        };
        (files, Some(me.series))
    };
    let mut by_series: BTreeMap<String, Vec<Scanned>> = BTreeMap::new();
    for f in files {
        by_series.entry(f.series.clone()).or_default().push(f);
    }
    let series = match chosen_series {
        Some(uid) => by_series.remove(&uid).unwrap_or_default(),
        None if by_series.len() == 1 => by_series.into_values().next().unwrap_or_default(),
        None => {
            let list: Vec<String> = by_series
                .iter()
                .map(|(uid, fs)| {
                    format!(
                        "{uid} \"{}\" ({} file{}, e.g. {})",
                        fs[0].description,
                        fs.len(),
                        if fs.len() == 1 { "" } else { "s" },
                        fs[0].path.display()
                    )
                })
                .collect();
            return Err(VolumeError::InvalidArgument(format!(
                "the folder holds {} DICOM series; read one by giving any file of it: {}",
                list.len(),
                list.join("; ")
            )));
        }
    };
    if series.len() == 1 && series[0].multiframe {
        return read_multiframe(&series[0].path);
    }
    if let Some(m) = series.iter().find(|s| s.multiframe) {
        return Err(VolumeError::Unsupported(format!(
            "series mixes multi-frame files ({}) with single slices",
            m.path.display()
        )));
    }
    read_series(&series)
}

fn read_series(series: &[Scanned]) -> Result<(AnyVolume, Header), VolumeError> {
    let names: Vec<String> = series
        .iter()
        .map(|s| s.path.display().to_string())
        .collect();
    let (volume, mut header) = read_slices(
        &names,
        |i| open_header(&series[i].path).ok_or_else(|| err(format!("{}: unreadable", names[i]))),
        |i| open_full(&series[i].path),
    )?;
    header
        .fields
        .push(("files".into(), series.len().to_string()));
    Ok((volume, header))
}

/// A stack of single-frame slices named `names`: `header(i)` opens slice `i` without its
/// pixels, `full(i)` with them (one slice in memory at a time).
fn read_slices<H, F>(
    names: &[String],
    header: impl Fn(usize) -> Result<H, VolumeError>,
    full: impl Fn(usize) -> Result<F, VolumeError>,
) -> Result<(AnyVolume, Header), VolumeError>
where
    H: Borrow<DefaultDicomObject>,
    F: Borrow<DefaultDicomObject>,
{
    let mut planes = Vec::with_capacity(names.len());
    let mut format: Option<PixelFormat> = None;
    let mut first: Option<H> = None;
    for (i, what) in names.iter().enumerate() {
        let h = header(i)?;
        let obj: &DefaultDicomObject = h.borrow();
        let pf = PixelFormat::of(obj, what)?;
        match format {
            None => format = Some(pf),
            Some(f) if f != pf => {
                return Err(err(format!(
                    "{what}: its pixels ({pf:?}) differ from the series' ({f:?})"
                )));
            }
            Some(_) => {}
        }
        let (position, row_dir, col_dir, spacing) = plane_from(
            what,
            floats(obj, tags::IMAGE_ORIENTATION_PATIENT),
            floats(obj, tags::IMAGE_POSITION_PATIENT),
            floats(obj, tags::PIXEL_SPACING),
        )?;
        planes.push(Plane {
            position,
            row_dir,
            col_dir,
            spacing,
            slope: float(obj, tags::RESCALE_SLOPE).unwrap_or(1.0) * dose_scaling(obj),
            intercept: float(obj, tags::RESCALE_INTERCEPT).unwrap_or(0.0),
            file: i,
            frame: 0,
        });
        if first.is_none() {
            first = Some(h);
        }
    }
    let first = first.ok_or_else(|| err("empty series"))?;
    let first: &DefaultDicomObject = first.borrow();
    let format = format.ok_or_else(|| err("empty series"))?;
    let single_step =
        float(first, tags::SPACING_BETWEEN_SLICES).or_else(|| float(first, tags::SLICE_THICKNESS));
    let (geometry, order) = assemble(&mut planes, single_step, &|p: &Plane| names[p.file].clone())?;
    let header = summary(first, &format, &planes, geometry);
    // Decode slice by slice (one file at a time in memory).
    let one_slice = format.frame_bytes() as u64;
    let volume = fill(&format, &planes, &order, geometry, one_slice, |p, sink| {
        let obj = full(p.file)?;
        decode_frame(obj.borrow(), &format, 0, &names[p.file], sink)
    })?;
    Ok((volume, header))
}

fn read_multiframe(path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    read_multiframe_object(&open_full(path)?, &path.display().to_string())
}

/// Read one DICOM file held in memory (with or without the 128-byte preamble and `DICM`
/// magic): a multi-frame file's frames, or a single slice as a one-slice volume (its slice
/// step from `SpacingBetweenSlices` or `SliceThickness`, else 1). The in-memory entry point
/// of the DICOM reader (fuzzing, files that are not on disk); a folder or a series needs
/// [`crate::read`].
///
/// # Errors
/// [`VolumeError::Format`] for bytes that are not a DICOM image, missing or inconsistent
/// patient geometry, or undecodable pixel data; [`VolumeError::Unsupported`] for colour images,
/// `BitsAllocated` other than 8, 16 or 32 and transfer syntaxes without a decoder;
/// [`VolumeError::Io`] when the pixel matrix exceeds the memory budget.
pub fn read_bytes(bytes: &[u8]) -> Result<(AnyVolume, Header), VolumeError> {
    let what = "DICOM data";
    check_declared_lengths(bytes, false, what)?;
    let open = || {
        OpenFileOptions::new()
            .read_preamble(dicom_object::file::ReadPreamble::Auto)
            .from_reader(bytes)
            .map_err(|e| err(format!("{what}: {e}")))
    };
    let mut obj = open()?;
    retype_un(&mut obj);
    if is_multiframe(&obj) {
        return read_multiframe_object(&obj, what);
    }
    // The pixel data is in memory already: refuse one too short for its frame before the
    // volume is allocated (Rows and Columns alone could ask for the whole memory budget).
    check_frames_present(&obj, &PixelFormat::of(&obj, what)?, 1, what)?;
    let names = [what.to_owned()];
    read_slices(&names, |_| Ok(&obj), |_| Ok(&obj))
}

fn read_multiframe_object(
    obj: &DefaultDicomObject,
    what: &str,
) -> Result<(AnyVolume, Header), VolumeError> {
    let what = what.to_owned();
    let format = PixelFormat::of(obj, &what)?;
    let frames = int(obj, tags::NUMBER_OF_FRAMES).unwrap_or(1).max(1);
    let frames =
        u32::try_from(frames).map_err(|_| err(format!("{what}: NumberOfFrames {frames}")))?;
    check_frames_present(obj, &format, frames, &what)?;
    let shared = item(obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
    let per_frame: &[InMemDicomObject] = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .unwrap_or(&[]);
    // A functional-group attribute: per-frame first, then shared, then the top level.
    let fg = |f: usize, seq, tag| -> Option<Vec<f64>> {
        per_frame
            .get(f)
            .and_then(|it| item(it, seq))
            .and_then(|s| floats(s, tag))
            .or_else(|| {
                shared
                    .and_then(|it| item(it, seq))
                    .and_then(|s| floats(s, tag))
            })
    };
    let enhanced = !per_frame.is_empty() || shared.is_some();
    // Fewer groups than frames leave frames without a place: refused. More groups than
    // frames (files cut down to their first frames, as pydicom's `liver_1frame.dcm`, keep the
    // whole sequence) give frame `f` the group `f`, as GDCM and pydicom do; the header says
    // how many were ignored.
    if enhanced && per_frame.len() < frames as usize {
        return Err(err(format!(
            "{what}: {} per-frame functional groups for {frames} frames",
            per_frame.len()
        )));
    }
    let extra_groups = if enhanced {
        per_frame.len() - frames as usize
    } else {
        0
    };
    let mut planes = Vec::with_capacity(frames as usize);
    let top_step =
        float(obj, tags::SPACING_BETWEEN_SLICES).or_else(|| float(obj, tags::SLICE_THICKNESS));
    let grid_offsets = grid_frame_offsets(obj, frames as usize, &what)?;
    for f in 0..frames as usize {
        let fw = format!("{what} frame {}", f + 1);
        let (ipp, iop, ps, slope, inter) = if enhanced {
            (
                fg(
                    f,
                    tags::PLANE_POSITION_SEQUENCE,
                    tags::IMAGE_POSITION_PATIENT,
                )
                .or_else(|| floats(obj, tags::IMAGE_POSITION_PATIENT)),
                fg(
                    f,
                    tags::PLANE_ORIENTATION_SEQUENCE,
                    tags::IMAGE_ORIENTATION_PATIENT,
                )
                .or_else(|| floats(obj, tags::IMAGE_ORIENTATION_PATIENT)),
                fg(f, tags::PIXEL_MEASURES_SEQUENCE, tags::PIXEL_SPACING)
                    .or_else(|| floats(obj, tags::PIXEL_SPACING)),
                fg(
                    f,
                    tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE,
                    tags::RESCALE_SLOPE,
                )
                .and_then(|v| v.first().copied())
                .or_else(|| float(obj, tags::RESCALE_SLOPE)),
                fg(
                    f,
                    tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE,
                    tags::RESCALE_INTERCEPT,
                )
                .and_then(|v| v.first().copied())
                .or_else(|| float(obj, tags::RESCALE_INTERCEPT)),
            )
        } else {
            // Classic multi-frame: frames placed along the normal from the top-level position,
            // by the RT Dose GridFrameOffsetVector or stepped by the slice spacing.
            let iop = floats(obj, tags::IMAGE_ORIENTATION_PATIENT);
            let ipp = floats(obj, tags::IMAGE_POSITION_PATIENT);
            let offset = match &grid_offsets {
                Some(v) => v[f] - v[0],
                None => {
                    let step = top_step.ok_or_else(|| {
                        err(format!(
                            "{what}: a multi-frame image without functional groups needs \
                             GridFrameOffsetVector, SpacingBetweenSlices or SliceThickness \
                             to place its frames"
                        ))
                    })?;
                    step * f as f64
                }
            };
            let ipp = match (&iop, ipp) {
                (Some(o), Some(p)) if o.len() == 6 && p.len() == 3 => {
                    let n = DVec3::new(o[0], o[1], o[2]).cross(DVec3::new(o[3], o[4], o[5]));
                    let q = DVec3::new(p[0], p[1], p[2]) + n.normalize_or_zero() * offset;
                    Some(q.to_array().to_vec())
                }
                (_, p) => p,
            };
            (
                ipp,
                iop,
                floats(obj, tags::PIXEL_SPACING),
                float(obj, tags::RESCALE_SLOPE),
                float(obj, tags::RESCALE_INTERCEPT),
            )
        };
        let slope = slope.unwrap_or(1.0) * dose_scaling(obj);
        let (position, row_dir, col_dir, spacing) = plane_from(&fw, iop, ipp, ps)?;
        planes.push(Plane {
            position,
            row_dir,
            col_dir,
            spacing,
            slope,
            intercept: inter.unwrap_or(0.0),
            file: 0,
            frame: f as u32,
        });
    }
    let single_step = top_step.or_else(|| {
        fg(0, tags::PIXEL_MEASURES_SEQUENCE, tags::SLICE_THICKNESS).and_then(|v| v.first().copied())
    });
    let (geometry, order) = assemble(&mut planes, single_step, &|p: &Plane| {
        format!("{what} frame {}", p.frame + 1)
    })?;
    let mut header = summary(obj, &format, &planes, geometry);
    header.fields.push(("frames".into(), frames.to_string()));
    if extra_groups > 0 {
        header.fields.push((
            "per-frame functional groups".into(),
            format!(
                "{} for {frames} frames: the last {extra_groups} (beyond NumberOfFrames) ignored",
                per_frame.len()
            ),
        ));
    }
    // Check the volume and every decoded frame together before decoding anything.
    let all_frames = (format.frame_bytes() as u64).saturating_mul(u64::from(frames));
    let (vt, _) = output_type(&format, &planes);
    let out = volmorph_io::checked_len(&[format.cols, format.rows, planes.len()], vt.size())?;
    volmorph_io::check_bytes(
        &format!("{what}: the volume and its decoded pixel data"),
        (out as u64 * vt.size() as u64).saturating_add(all_frames),
    )?;
    let pixels = Pixels::of(obj, &format, &what)?;
    let swapped = halves_swapped(obj, &format);
    let volume = fill(&format, &planes, &order, geometry, all_frames, |p, sink| {
        sink(&pixels.frame(&format, p.frame, &what)?, swapped);
        Ok(())
    })?;
    Ok((volume, header))
}

/// Check that the `PixelData` of `obj` can hold `frames` frames before anything per frame is
/// built: native data must have `frames · rows · cols · BitsAllocated / 8` bytes, and
/// encapsulated data at least one fragment per frame (PS3.5 A.4: a fragment never holds
/// data of two frames). This bounds the work and memory a forged `NumberOfFrames` can ask
/// for by the size of the file.
///
/// # Errors
/// No `PixelData`, or too little of it for `frames` frames.
fn check_frames_present(
    obj: &DefaultDicomObject,
    format: &PixelFormat,
    frames: u32,
    what: &str,
) -> Result<(), VolumeError> {
    use dicom_core::value::Value;
    let e = obj
        .element(tags::PIXEL_DATA)
        .map_err(|_| err(format!("{what}: no PixelData")))?;
    match e.value() {
        Value::PixelSequence(seq) => {
            let have = seq.fragments().len();
            if have < frames as usize {
                return Err(err(format!(
                    "{what}: NumberOfFrames {frames} but the encapsulated PixelData holds \
                     {have} fragments (each frame needs at least one)"
                )));
            }
        }
        Value::Primitive(p) => {
            let have = p.calculate_byte_len() as u64;
            let need = format.native_bytes(frames);
            if have < need {
                return Err(err(format!(
                    "{what}: NumberOfFrames {frames} of {}×{} {}-bit pixels need {need} bytes \
                     of PixelData; it holds {have}",
                    format.rows, format.cols, format.bits_allocated
                )));
            }
        }
        Value::Sequence(_) => {
            return Err(err(format!("{what}: PixelData is a sequence of items")));
        }
    }
    Ok(())
}

/// `DoseGridScaling` (RT Dose, PS3.3 C.8.8.3): the factor from stored values to dose in Gy,
/// applied like a rescale slope; 1 for other images.
fn dose_scaling(obj: &InMemDicomObject) -> f64 {
    float(obj, tags::DOSE_GRID_SCALING)
        .filter(|s| s.is_finite() && *s != 0.0)
        .unwrap_or(1.0)
}

/// The RT Dose `GridFrameOffsetVector` (PS3.3 C.8.8.3.2) of a multi-frame file with `frames`
/// frames: the frames' offsets along the slice normal. Whether the vector is relative (its
/// first element 0) or absolute (its first element the z of `ImagePositionPatient`, axial
/// doses only), frame `f` lies at `ImagePositionPatient + n · (v[f] − v[0])`.
///
/// # Errors
/// A vector whose length is not the frame count, or that is not finite.
fn grid_frame_offsets(
    obj: &InMemDicomObject,
    frames: usize,
    what: &str,
) -> Result<Option<Vec<f64>>, VolumeError> {
    let Some(v) = floats(obj, tags::GRID_FRAME_OFFSET_VECTOR) else {
        return Ok(None);
    };
    if v.len() != frames || v.iter().any(|x| !x.is_finite()) {
        return Err(err(format!(
            "{what}: GridFrameOffsetVector holds {} values for {frames} frames",
            v.len()
        )));
    }
    Ok(Some(v))
}

fn pixel_error(what: &str, e: &str) -> VolumeError {
    if e.contains("nsupported") || e.contains("not supported") {
        VolumeError::Unsupported(format!("{what}: pixel data: {e}"))
    } else {
        err(format!("{what}: pixel data: {e}"))
    }
}

/// Decode frame `frame` of `obj` and hand its bytes to `sink` (see [`fill`]).
fn decode_frame(
    obj: &DefaultDicomObject,
    format: &PixelFormat,
    frame: u32,
    what: &str,
    sink: &mut dyn FnMut(&[u8], bool),
) -> Result<(), VolumeError> {
    let pixels = Pixels::of(obj, format, what)?;
    sink(
        &pixels.frame(format, frame, what)?,
        halves_swapped(obj, format),
    );
    Ok(())
}

/// The pixel data of an object, decoded by dicom-rs, or (RLE Lossless with 32-bit samples,
/// which its RLE decoder does not read; PS3.5 Annex G allows it) the RLE fragments, one per
/// frame, decoded frame by frame by [`rle`], or native 1-bit pixels (segmentation masks,
/// PS3.5 8.1.1: packed least significant bit first, frames following each other bit by bit),
/// unpacked frame by frame to one byte (0 or 1) per pixel.
enum Pixels<'a> {
    Decoded(dicom_pixeldata::DecodedPixelData<'a>),
    Rle32(&'a [Vec<u8>]),
    /// `OB` data as bytes.
    Bits8(&'a [u8]),
    /// `OW` data as the words the parser read (in either byte order of the file, the bits
    /// run from the least significant of each word).
    Bits16(&'a [u16]),
}

impl<'a> Pixels<'a> {
    fn of(
        obj: &'a DefaultDicomObject,
        format: &PixelFormat,
        what: &str,
    ) -> Result<Self, VolumeError> {
        const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";
        let syntax = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']);
        if syntax == RLE_LOSSLESS && format.bits_allocated == 32 {
            let fragments = obj
                .element(tags::PIXEL_DATA)
                .ok()
                .and_then(|e| e.value().fragments())
                .ok_or_else(|| err(format!("{what}: RLE pixel data is not encapsulated")))?;
            return Ok(Self::Rle32(fragments));
        }
        if format.bits_allocated == 1 {
            use dicom_core::value::{PrimitiveValue, Value};
            let e = obj
                .element(tags::PIXEL_DATA)
                .map_err(|_| err(format!("{what}: no PixelData")))?;
            return match e.value() {
                Value::Primitive(PrimitiveValue::U8(b)) => Ok(Self::Bits8(b)),
                Value::Primitive(PrimitiveValue::U16(w)) => Ok(Self::Bits16(w)),
                Value::PixelSequence(_) => Err(VolumeError::Unsupported(format!(
                    "{what}: compressed 1-bit pixel data (transfer syntax {syntax}); 1-bit \
                     images are read uncompressed"
                ))),
                _ => Err(err(format!("{what}: 1-bit PixelData is neither OB nor OW"))),
            };
        }
        obj.decode_pixel_data()
            .map(Self::Decoded)
            .map_err(|e| pixel_error(what, &e.to_string()))
    }

    /// The bytes of frame `frame`, checked to hold the whole frame.
    fn frame(
        &self,
        format: &PixelFormat,
        frame: u32,
        what: &str,
    ) -> Result<std::borrow::Cow<'_, [u8]>, VolumeError> {
        match self {
            Self::Decoded(d) => frame_bytes(d, format, frame, what).map(std::borrow::Cow::Borrowed),
            Self::Rle32(fragments) => {
                // PS3.5 A.4.2: each RLE frame is exactly one fragment.
                let fragment = fragments.get(frame as usize).ok_or_else(|| {
                    err(format!(
                        "{what}: frame {} has no RLE fragment ({} fragments)",
                        frame + 1,
                        fragments.len()
                    ))
                })?;
                rle::decode_u32_frame(fragment, format.rows * format.cols, what)
                    .map(std::borrow::Cow::Owned)
            }
            Self::Bits8(_) | Self::Bits16(_) => {
                let per = format.rows * format.cols;
                let first = per * frame as usize;
                let bit = |i: usize| match self {
                    Self::Bits8(b) => b.get(i / 8).map(|v| (v >> (i % 8)) & 1),
                    Self::Bits16(w) => w.get(i / 16).map(|v| ((v >> (i % 16)) & 1) as u8),
                    _ => None,
                };
                (first..first + per)
                    .map(|i| bit(i).ok_or_else(|| err(format!("{what}: pixel data truncated"))))
                    .collect::<Result<Vec<u8>, _>>()
                    .map(std::borrow::Cow::Owned)
            }
        }
    }
}

/// Whether the decoded bytes of 32-bit pixels have their 16-bit halves swapped: an explicit VR
/// big endian file whose `PixelData` has VR `OW` is parsed as native 16-bit words (PS3.5
/// §8.2: `OW` is byte-swapped per word), so each 32-bit value arrives as its high word then its
/// low word, each little-endian. (`OL` data and little-endian files come out in order.)
fn halves_swapped(obj: &DefaultDicomObject, format: &PixelFormat) -> bool {
    use dicom_core::value::{PrimitiveValue, Value};
    const EXPLICIT_VR_BIG_ENDIAN: &str = "1.2.840.10008.1.2.2";
    format.bits_allocated == 32
        && obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']) == EXPLICIT_VR_BIG_ENDIAN
        && obj
            .element(tags::PIXEL_DATA)
            .is_ok_and(|e| matches!(e.value(), Value::Primitive(PrimitiveValue::U16(_))))
}

/// The bytes of frame `frame` of `decoded`, checked to hold the whole frame.
fn frame_bytes<'a>(
    decoded: &'a dicom_pixeldata::DecodedPixelData<'_>,
    format: &PixelFormat,
    frame: u32,
    what: &str,
) -> Result<&'a [u8], VolumeError> {
    let bytes = decoded
        .frame_data(frame)
        .map_err(|e| err(format!("{what}: frame {}: {e}", frame + 1)))?;
    if bytes.len() < format.frame_bytes() {
        return Err(err(format!("{what}: pixel data truncated")));
    }
    Ok(bytes)
}

/// Sort the planes along the normal, check them, and derive the geometry. Returns the
/// geometry and the plane index of each slice `k`.
fn assemble(
    planes: &mut [Plane],
    single_step: Option<f64>,
    name: &dyn Fn(&Plane) -> String,
) -> Result<(Geometry, Vec<usize>), VolumeError> {
    let p0 = planes.first().ok_or_else(|| err("no slices"))?.clone();
    for p in planes.iter() {
        let off = (p.row_dir - p0.row_dir)
            .abs()
            .max_element()
            .max((p.col_dir - p0.col_dir).abs().max_element());
        if off > ORIENTATION_TOL {
            return Err(err(format!(
                "{}: orientation {:?}/{:?} differs from {}'s {:?}/{:?}: the series is not one \
                 stack of parallel slices",
                name(p),
                p.row_dir.to_array(),
                p.col_dir.to_array(),
                name(&p0),
                p0.row_dir.to_array(),
                p0.col_dir.to_array()
            )));
        }
        let ds = (p.spacing[0] - p0.spacing[0])
            .abs()
            .max((p.spacing[1] - p0.spacing[1]).abs());
        if ds > 1e-6 * p0.spacing[0].max(p0.spacing[1]) {
            return Err(err(format!(
                "{}: PixelSpacing {:?} differs from the series' {:?}",
                name(p),
                p.spacing,
                p0.spacing
            )));
        }
    }
    let normal = p0.row_dir.cross(p0.col_dir).normalize();
    let mut order: Vec<usize> = (0..planes.len()).collect();
    let d = |i: usize| normal.dot(planes[i].position);
    order.sort_by(|&a, &b| d(a).total_cmp(&d(b)));
    let n = order.len();
    for w in order.windows(2) {
        if d(w[1]) - d(w[0]) < SAME_POSITION_TOL {
            return Err(VolumeError::Unsupported(format!(
                "{} and {} lie at the same position along the slice normal ({:.4} mm): the \
                 series holds several volumes (acquisitions, echoes or time points); split it",
                name(&planes[w[0]]),
                name(&planes[w[1]]),
                volmorph_io::Num(d(w[0]))
            )));
        }
    }
    let first = planes[order[0]].position;
    let (axis, step) = if n > 1 {
        let last = planes[order[n - 1]].position;
        let mean = (d(order[n - 1]) - d(order[0])) / (n - 1) as f64;
        let worst = order
            .windows(2)
            .max_by(|a, b| {
                let dev = |w: &[usize]| (d(w[1]) - d(w[0]) - mean).abs();
                dev(a).total_cmp(&dev(b))
            })
            .map(<[usize]>::to_vec);
        if let Some(w) = worst {
            let gap = d(w[1]) - d(w[0]);
            if (gap - mean).abs() > SLICE_GAP_TOL * mean {
                return Err(err(format!(
                    "slices are not evenly spaced: {} → {} is {:.4} mm, the mean step is {:.4} \
                     mm (a missing slice, or several stacks in one series)",
                    name(&planes[w[0]]),
                    name(&planes[w[1]]),
                    volmorph_io::Num(gap),
                    volmorph_io::Num(mean)
                )));
            }
        }
        let v = (last - first) / (n - 1) as f64;
        (v / v.length(), v.length())
    } else {
        let s = single_step
            .filter(|s| s.is_finite() && *s > 0.0)
            .unwrap_or(1.0);
        (normal, s)
    };
    let geometry = Geometry {
        dims: [1, 1, n], // the pixel matrix is set by `fill`
        spacing: DVec3::new(p0.spacing[0], p0.spacing[1], step),
        origin: first,
        direction: DMat3::from_cols(p0.row_dir, p0.col_dir, axis),
    };
    Ok((geometry, order))
}

/// Header fields for `info`.
fn summary(
    obj: &InMemDicomObject,
    format: &PixelFormat,
    planes: &[Plane],
    geometry: Geometry,
) -> Header {
    let mut f: Vec<(String, String)> = Vec::new();
    for (k, tag) in [
        ("Modality", tags::MODALITY),
        ("Manufacturer", tags::MANUFACTURER),
        ("SeriesDescription", tags::SERIES_DESCRIPTION),
        ("SeriesInstanceUID", tags::SERIES_INSTANCE_UID),
        ("SOPClassUID", tags::SOP_CLASS_UID),
        (
            "PhotometricInterpretation",
            tags::PHOTOMETRIC_INTERPRETATION,
        ),
        ("SliceThickness", tags::SLICE_THICKNESS),
    ] {
        if let Some(v) = text(obj, tag) {
            f.push((k.into(), v));
        }
    }
    f.push((
        "pixels".into(),
        format!(
            "{} columns × {} rows, {} bits allocated, {} stored, {}",
            format.cols,
            format.rows,
            format.bits_allocated,
            format.bits_stored,
            if format.signed { "signed" } else { "unsigned" }
        ),
    ));
    f.push(("slices".into(), planes.len().to_string()));
    let rescales: std::collections::BTreeSet<String> = planes
        .iter()
        .map(|p| format!("slope {} intercept {}", p.slope, p.intercept))
        .collect();
    f.push((
        "rescale".into(),
        if rescales.len() == 1 {
            rescales.into_iter().next().unwrap_or_default()
        } else {
            format!("{} different per slice", rescales.len())
        },
    ));
    f.push(("slice step".into(), format!("{} mm", geometry.spacing.z)));
    Header { fields: f }
}

/// The voxel type of the rescaled values (see the module docs).
fn output_type(format: &PixelFormat, planes: &[Plane]) -> (VoxelType, bool) {
    let b = planes[0].intercept;
    let integral = planes
        .iter()
        .all(|p| p.slope == 1.0 && p.intercept == b && b.fract() == 0.0);
    if !integral {
        return (VoxelType::F32, false);
    }
    let (lo, hi) = format.range();
    let (lo, hi) = (lo + b, hi + b);
    for t in [
        VoxelType::U8,
        VoxelType::I8,
        VoxelType::U16,
        VoxelType::I16,
        VoxelType::U32,
        VoxelType::I32,
    ] {
        let (tl, th) = t.range();
        if tl <= lo && hi <= th {
            return (t, true);
        }
    }
    (VoxelType::F64, false)
}

/// Allocate the volume and fill it slice by slice. `decoded_bytes` is the largest decoded pixel
/// buffer held while filling (one slice of a series, or every frame of a multi-frame file):
/// the output and that buffer are checked together against the memory budget before either
/// is allocated. `frame(p, sink)` hands the little-endian bytes of plane `p`'s frame (at least
/// `rows · cols · BitsAllocated / 8` of them; see [`frame_bytes`]) and whether their 16-bit
/// halves are swapped to `sink`, which rescales them straight into the
/// output slice: no intermediate per-voxel buffer.
fn fill(
    format: &PixelFormat,
    planes: &[Plane],
    order: &[usize],
    mut geometry: Geometry,
    decoded_bytes: u64,
    mut frame: impl FnMut(&Plane, &mut dyn FnMut(&[u8], bool)) -> Result<(), VolumeError>,
) -> Result<AnyVolume, VolumeError> {
    geometry.dims = [format.cols, format.rows, order.len()];
    let (vt, _) = output_type(format, planes);
    let n = volmorph_io::checked_len(&geometry.dims, vt.size())?;
    let out_bytes = n as u64 * vt.size() as u64;
    volmorph_io::check_bytes(
        "DICOM volume and its decoded pixel data",
        out_bytes.saturating_add(decoded_bytes),
    )?;
    geometry.validate()?;
    let per = format.cols * format.rows;
    Ok(volmorph_volume::with_voxel_type!(vt, T => {
        let mut data: Vec<T> = volmorph_io::try_vec("DICOM volume", n, T::default())?;
        for (k, &pi) in order.iter().enumerate() {
            let p = &planes[pi];
            let out = &mut data[k * per..(k + 1) * per];
            frame(p, &mut |bytes: &[u8], swapped: bool| {
                for (i, o) in out.iter_mut().enumerate() {
                    let s = if swapped {
                        let b = &bytes[4 * i..4 * i + 4];
                        format.value(&[b[2], b[3], b[0], b[1]], 0)
                    } else {
                        format.value(bytes, i)
                    };
                    // slope·v + intercept, as ITK/GDCM apply it.
                    *o = T::from_f64(s as f64 * p.slope + p.intercept);
                }
            })?;
        }
        AnyVolume::from(Volume::new(geometry, data)?)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(z: f64, file: usize) -> Plane {
        Plane {
            position: DVec3::new(1.0, 2.0, z),
            row_dir: DVec3::X,
            col_dir: DVec3::Y,
            spacing: [0.5, 0.5],
            slope: 1.0,
            intercept: 0.0,
            file,
            frame: 0,
        }
    }

    #[test]
    fn slices_are_sorted_along_the_normal_and_checked() {
        let name = |p: &Plane| format!("slice {}", p.file);
        let mut ps = vec![plane(5.0, 0), plane(1.0, 1), plane(3.0, 2)];
        let (g, order) = assemble(&mut ps, None, &name).unwrap();
        assert_eq!(order, vec![1, 2, 0]);
        assert_eq!(g.origin, DVec3::new(1.0, 2.0, 1.0));
        assert_eq!(g.spacing, DVec3::new(0.5, 0.5, 2.0));
        assert_eq!(g.direction, DMat3::IDENTITY);
        // A missing slice.
        let mut ps = vec![plane(1.0, 0), plane(3.0, 1), plane(7.0, 2), plane(9.0, 3)];
        let e = assemble(&mut ps, None, &name).unwrap_err().to_string();
        assert!(
            e.contains("not evenly spaced") && e.contains("slice 1 → slice 2"),
            "{e}"
        );
        // Two stacks at the same positions.
        let mut ps = vec![plane(1.0, 0), plane(1.0, 1)];
        let e = assemble(&mut ps, None, &name).unwrap_err().to_string();
        assert!(e.contains("same position"), "{e}");
        // One slice: the step from SliceThickness.
        let mut ps = vec![plane(1.0, 0)];
        let (g, _) = assemble(&mut ps, Some(2.5), &name).unwrap();
        assert_eq!(g.spacing.z, 2.5);
    }

    #[test]
    fn tilted_gantry_gives_the_sheared_axis() {
        let name = |p: &Plane| format!("slice {}", p.file);
        // Each slice moves 2 along z and 0.5 along y: the third axis is not the normal.
        let mut ps: Vec<Plane> = (0..4)
            .map(|k| {
                let mut p = plane(2.0 * k as f64, k);
                p.position.y += 0.5 * k as f64;
                p
            })
            .collect();
        let (g, _) = assemble(&mut ps, None, &name).unwrap();
        let want = DVec3::new(0.0, 0.5, 2.0);
        assert!((g.direction.z_axis * g.spacing.z - want).length() < 1e-12);
        // Every slice's first voxel lands on its position.
        for (k, p) in ps.iter().enumerate() {
            let x = g.index_to_physical(DVec3::new(0.0, 0.0, k as f64));
            assert!((x - p.position).length() < 1e-12);
        }
    }

    #[test]
    fn stored_bits_are_masked_and_sign_extended() {
        let f = PixelFormat {
            rows: 1,
            cols: 3,
            bits_allocated: 16,
            bits_stored: 12,
            signed: true,
        };
        let bytes: Vec<u8> = [0x0fffu16, 0x0800, 0xf7ff]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(f.value(&bytes, 0), -1);
        assert_eq!(f.value(&bytes, 1), -2048);
        assert_eq!(f.value(&bytes, 2), 2047); // high (overlay) bits ignored
        let u = PixelFormat { signed: false, ..f };
        assert_eq!(u.value(&bytes, 0), 4095);
        assert_eq!(u.range(), (0.0, 4095.0));
        // CT: 12 stored bits, intercept −1024 → i16.
        let mut p = plane(0.0, 0);
        p.intercept = -1024.0;
        assert_eq!(output_type(&u, &[p.clone()]).0, VoxelType::I16);
        p.slope = 0.5;
        assert_eq!(output_type(&u, &[p]).0, VoxelType::F32);
    }

    /// The path and bytes of a file of `tests/corpus/peers`.
    fn corpus_file(name: &str) -> (PathBuf, Vec<u8>) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/corpus/peers")
            .join(name);
        let bytes = std::fs::read(&path).unwrap();
        (path, bytes)
    }

    /// The path and bytes of a corpus file that [`read_bytes`] must refuse with an error
    /// containing `message`.
    fn refused_corpus_file(name: &str, message: &str) -> (PathBuf, Vec<u8>) {
        let (path, bytes) = corpus_file(name);
        let e = read_bytes(&bytes).unwrap_err().to_string();
        assert!(e.contains(message), "{name}: {e}");
        (path, bytes)
    }

    /// The DICOM file `bytes`, parsed.
    fn open(bytes: &[u8]) -> DefaultDicomObject {
        OpenFileOptions::new()
            .read_preamble(dicom_object::file::ReadPreamble::Auto)
            .from_reader(bytes)
            .unwrap()
    }

    /// The DICOM file `bytes` with `element` put in (replacing one of its tag), as bytes.
    fn with_element(bytes: &[u8], element: dicom_core::DataElement<InMemDicomObject>) -> Vec<u8> {
        let mut obj = open(bytes);
        obj.put(element);
        let mut out = Vec::new();
        obj.write_all(&mut out).unwrap();
        out
    }

    /// A corpus file with `NumberOfFrames` replaced by `frames`, as bytes.
    fn with_frame_count(name: &str, frames: &str) -> Vec<u8> {
        use dicom_core::{DataElement, PrimitiveValue};
        let (_, bytes) = corpus_file(name);
        with_element(
            &bytes,
            DataElement::new(tags::NUMBER_OF_FRAMES, VR::IS, PrimitiveValue::from(frames)),
        )
    }

    /// The per-frame functional groups of the DICOM file `bytes`.
    fn per_frame_groups(bytes: &[u8]) -> Vec<InMemDicomObject> {
        open(bytes)
            .element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
            .unwrap()
            .items()
            .unwrap()
            .to_vec()
    }

    /// The DICOM file `bytes` with its per-frame functional groups replaced by `groups`.
    fn with_per_frame_groups(bytes: &[u8], groups: Vec<InMemDicomObject>) -> Vec<u8> {
        use dicom_core::DataElement;
        use dicom_core::value::DataSetSequence;
        with_element(
            bytes,
            DataElement::new(
                tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE,
                VR::SQ,
                DataSetSequence::from(groups),
            ),
        )
    }

    /// pydicom's `rtdose_rle.dcm` (its RT Dose grid, 32-bit samples, stored RLE Lossless)
    /// was refused: the dicom-rs RLE decoder reads 8 and 16 bits. The same dose re-encoded
    /// as RLE, one fragment per frame (PS3.5 Annex G), reads as the uncompressed file does;
    /// a frame without its fragment is refused naming it.
    #[test]
    fn rle_dose_of_32_bit_samples_is_refused() {
        use dicom_core::value::{PixelFragmentSequence, Value};
        use dicom_core::{DataElement, PrimitiveValue};
        let (path, bytes) = corpus_file("pydicom_rtdose.dcm");
        let (plain, _) = read_bytes(&bytes).unwrap();
        let mut obj = OpenFileOptions::new().open_file(&path).unwrap();
        let format = PixelFormat::of(&obj, "x").unwrap();
        assert_eq!(format.bits_allocated, 32);
        let frame_len = format.frame_bytes();
        let raw = obj
            .element(tags::PIXEL_DATA)
            .unwrap()
            .to_bytes()
            .unwrap()
            .into_owned();
        let fragments: Vec<Vec<u8>> = raw
            .chunks_exact(frame_len)
            .map(|f| {
                let samples: Vec<u32> = f
                    .chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect();
                rle::tests::rle_u32_fragment(&samples)
            })
            .collect();
        assert_eq!(fragments.len(), plain.geometry().dims[2]);
        let encode = |obj: &DefaultDicomObject, fragments: Vec<Vec<u8>>| {
            let mut o = obj.clone();
            o.put(DataElement::new(
                tags::PIXEL_DATA,
                VR::OB,
                Value::from(PixelFragmentSequence::new(Vec::<u32>::new(), fragments)),
            ));
            o.meta_mut()
                .set_transfer_syntax(&dicom_transfer_syntax_registry::entries::RLE_LOSSLESS);
            let mut b = Vec::new();
            o.write_all(&mut b).unwrap();
            b
        };
        let (rle, _) = read_bytes(&encode(&obj, fragments.clone())).unwrap();
        assert_eq!(rle, plain);
        // One fragment short: the last frame has none.
        let mut short = fragments;
        short.pop();
        obj.put(DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from(format!("{}", short.len() + 1)),
        ));
        let e = read_bytes(&encode(&obj, short)).unwrap_err().to_string();
        assert!(e.contains("fragment"), "{e}");
    }

    /// pydicom's `liver_1frame.dcm` (a segmentation, `BitsAllocated` 1) was refused. The RT
    /// Dose's frames thresholded to a 1-bit mask (10 × 10 pixels: frames start in the middle
    /// of a byte) read back as that mask, packed in bytes (`OB`) and in words (`OW`).
    #[test]
    fn one_bit_segmentation_is_refused() {
        use dicom_core::{DataElement, PrimitiveValue};
        let (path, bytes) = corpus_file("pydicom_rtdose.dcm");
        let (plain, _) = read_bytes(&bytes).unwrap();
        let plain = plain.to_typed::<f64>();
        let mut obj = OpenFileOptions::new().open_file(&path).unwrap();
        let scale = dose_scaling(&obj);
        let raw = obj
            .element(tags::PIXEL_DATA)
            .unwrap()
            .to_bytes()
            .unwrap()
            .into_owned();
        let samples: Vec<u32> = raw
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let mut sorted = samples.clone();
        sorted.sort_unstable();
        let t = sorted[sorted.len() / 2];
        let mut packed = vec![0u8; samples.len().div_ceil(8)];
        for (i, &v) in samples.iter().enumerate() {
            if v > t {
                packed[i / 8] |= 1 << (i % 8);
            }
        }
        let [nx, ny, _] = plain.geometry().dims;
        assert_ne!(nx * ny % 8, 0, "frames must start inside a byte");
        for tag in [tags::BITS_ALLOCATED, tags::BITS_STORED] {
            obj.put(DataElement::new(tag, VR::US, PrimitiveValue::from(1u16)));
        }
        obj.put(DataElement::new(
            tags::HIGH_BIT,
            VR::US,
            PrimitiveValue::from(0u16),
        ));
        obj.remove_element(tags::DOSE_GRID_SCALING);
        let words: Vec<u16> = packed
            .chunks(2)
            .map(|c| u16::from(c[0]) | (u16::from(*c.get(1).unwrap_or(&0)) << 8))
            .collect();
        for (vr, value) in [
            (VR::OB, PrimitiveValue::U8(packed.clone().into())),
            (VR::OW, PrimitiveValue::U16(words.into())),
        ] {
            let mut o = obj.clone();
            o.put(DataElement::new(tags::PIXEL_DATA, vr, value));
            let mut b = Vec::new();
            o.write_all(&mut b).unwrap();
            let (mask, _) = read_bytes(&b).unwrap();
            assert_eq!(mask.voxel_type(), VoxelType::U8, "{vr:?}");
            assert_eq!(mask.geometry(), plain.geometry());
            let mask = mask.to_typed::<f64>();
            // Stored values are integers: v > t ⟺ dose / scale > t + 0.5.
            let want: Vec<f64> = plain
                .data()
                .iter()
                .map(|&d| f64::from(u8::from(d / scale > f64::from(t) + 0.5)))
                .collect();
            assert_eq!(mask.data(), &want[..], "{vr:?}");
        }
    }

    /// pydicom's `liver_1frame.dcm` (a one-frame segmentation) was refused for having no
    /// top-level `ImageOrientationPatient`: a file with one frame was read as a classic
    /// slice although its frame is placed by the functional groups. The enhanced CT cut to
    /// its first frame reads as that frame of the whole file.
    #[test]
    fn one_frame_enhanced_file_has_no_image_orientation() {
        let (_, bytes) = corpus_file("pydicom_enhanced_ct.dcm");
        let cut = with_frame_count("pydicom_enhanced_ct.dcm", "1");
        assert!(open(&cut).element(tags::IMAGE_ORIENTATION_PATIENT).is_err());
        let first_group = per_frame_groups(&cut).swap_remove(0);
        let one = with_per_frame_groups(&cut, vec![first_group]);
        let (all, _) = read_bytes(&bytes).unwrap();
        let (first, _) = read_bytes(&one).unwrap();
        assert_eq!(first.geometry().dims[2], 1);
        let (all, first) = (all.to_typed::<f64>(), first.to_typed::<f64>());
        let plane = first.data().len();
        // The first frame is the first or the last slice along the normal.
        let a = all.data();
        assert!(
            first.data() == &a[..plane] || first.data() == &a[a.len() - plane..],
            "the one frame is not a slice of the whole file"
        );
    }

    /// Regression (pydicom's `liver_1frame.dcm`): a file cut down to its first frame keeps
    /// every per-frame functional group; it was refused ("3 per-frame functional groups for 1
    /// frames") though pydicom reads it. Frame `f` takes group `f`, the header names the
    /// ignored groups, and fewer groups than frames is still refused.
    #[test]
    fn one_frame_cut_from_an_enhanced_file_keeps_every_functional_group() {
        let cut = with_frame_count("pydicom_enhanced_ct.dcm", "1");
        let groups = per_frame_groups(&cut);
        assert!(groups.len() > 1);
        let (v, header) = read_bytes(&cut).unwrap();
        assert_eq!(v.geometry().dims[2], 1);
        let note = header
            .fields
            .iter()
            .find(|(k, _)| k == "per-frame functional groups")
            .map(|(_, v)| v.clone())
            .expect("the ignored groups are named");
        assert!(
            note.contains(&format!("last {}", groups.len() - 1)),
            "{note}"
        );
        // The same as the file whose sequence holds the first group only.
        let one = with_per_frame_groups(&cut, vec![groups[0].clone()]);
        let (w, _) = read_bytes(&one).unwrap();
        assert_eq!(v.geometry(), w.geometry());
        assert_eq!(v.to_typed::<f64>().data(), w.to_typed::<f64>().data());
        // Fewer groups than frames: refused.
        let (_, bytes) = corpus_file("pydicom_enhanced_ct.dcm");
        let short = with_per_frame_groups(&bytes, vec![groups[0].clone()]);
        let e = read_bytes(&short).unwrap_err().to_string();
        assert!(e.contains("1 per-frame functional groups for"), "{e}");
    }

    /// Regression (fuzzing, out of memory): a forged `NumberOfFrames` of two billion made the
    /// multi-frame reader reserve a plane per frame (hundreds of GB) before looking at the
    /// pixel data. The frame count is now checked against the `PixelData` first.
    #[test]
    fn forged_frame_count_is_refused_before_allocating() {
        for name in ["pydicom_rtdose.dcm", "pydicom_enhanced_ct.dcm"] {
            let bytes = with_frame_count(name, "2000000000");
            let e = read_bytes(&bytes).unwrap_err().to_string();
            assert!(e.contains("NumberOfFrames 2000000000"), "{name}: {e}");
            assert!(e.contains("PixelData"), "{name}: {e}");
        }
        // The true count still reads.
        let (v, _) = read_bytes(&with_frame_count("pydicom_rtdose.dcm", "3")).unwrap();
        assert_eq!(v.geometry().dims[2], 3);
    }

    /// Fuzz `dicom` (oom-a92a376a…, a 2 GiB allocation from a 411-byte file): the meta
    /// group ended, for the length walk, at the first element of another group, but the
    /// parser reads meta elements of any group until the (0002,0000) group length is used
    /// up. The walk started the data set 12 bytes early and missed the group length
    /// (0000,0000) of 2³¹ bytes the parser then read. The walk now ends the meta group as
    /// the parser does.
    #[test]
    fn meta_group_ends_where_its_group_length_says() {
        let (path, bytes) =
            refused_corpus_file("meta_group_length_overrun.dcm", "declares 2147483648 bytes");
        // Without the preamble (`DICM` at 0) the walk runs too.
        let e = check_declared_lengths(&bytes[128..], false, "x").unwrap_err();
        assert!(e.to_string().contains("declares 2147483648 bytes"), "{e}");
        // And from the file, header scan and full read alike.
        assert!(check_declared_lengths_of_file(&path, true).is_err());
        assert!(check_declared_lengths_of_file(&path, false).is_err());
    }

    /// Fuzz `dicom` (an 811 MB allocation found under `ulimit -v`, RSS creeping past
    /// libFuzzer's 2 GB limit in CI): a 638-byte implicit-VR file whose group length
    /// (3000,0000), a UL, declares 14 bytes. The parser reads three numbers (12 bytes) and
    /// takes the last two bytes as the start of the next header, which then declared
    /// 811 335 711 bytes; the length walk had skipped all 14 and never saw that header.
    /// The walk now consumes a numeric value as the parser does.
    #[test]
    fn misaligned_numeric_length_is_refused_before_allocating() {
        let (path, _) =
            refused_corpus_file("misaligned_numeric_length.dcm", "declares 811335711 bytes");
        assert!(check_declared_lengths_of_file(&path, false).is_err());
    }

    /// Fuzz `dicom` (oom-afd1d846…): an element with the unrecognised VR `\0\0` declared a
    /// 4.29 GB value. The parser reads an unknown VR as UN (2 reserved bytes, a 4-byte
    /// length), while the length walk took it for a 2-byte-length VR, read 30 bytes and let
    /// the forged length through to an allocation beyond the memory budget. The walk now
    /// reads every VR outside the 2-byte-length list as the parser does.
    #[test]
    fn unknown_vr_with_forged_length_is_refused_before_allocating() {
        let mut b = vec![0u8; 128];
        b.extend_from_slice(b"DICM");
        let meta_element = |b: &mut Vec<u8>, elem: u16, vr: &[u8; 2], value: &[u8]| {
            b.extend_from_slice(&2u16.to_le_bytes());
            b.extend_from_slice(&elem.to_le_bytes());
            b.extend_from_slice(vr);
            b.extend_from_slice(&(value.len() as u16).to_le_bytes());
            b.extend_from_slice(value);
        };
        meta_element(&mut b, 0x0000, b"UL", &28u32.to_le_bytes());
        meta_element(&mut b, 0x0010, b"UI", b"1.2.840.10008.1.2.1\0");
        // (0010,574F), VR "\0\0", reserved 0x001E, length 0xFFEC_0000, then a few bytes.
        b.extend_from_slice(&[0x10, 0x00, 0x4F, 0x57, 0, 0, 30, 0, 0, 0, 0xEC, 0xFF]);
        b.extend_from_slice(&[0u8; 24]);
        let e = read_bytes(&b).unwrap_err().to_string();
        assert!(e.contains("(0010,574F) declares 4293656576 bytes"), "{e}");
        // A known long VR (OB) and a short one (US) are walked as before.
        let mut ok = b[..b.len() - 36].to_vec();
        ok.extend_from_slice(&[0x28, 0x00, 0x10, 0x00, b'U', b'S', 2, 0, 4, 0]);
        ok.extend_from_slice(&[0x09, 0x00, 0x10, 0x00, b'O', b'B', 0, 0, 2, 0, 0, 0, 7, 7]);
        check_declared_lengths(&ok, false, "ok").unwrap();
    }

    /// Fuzz `dicom` (a 503 MB allocation from an 806-byte file, found under `ulimit -v`): the
    /// hand-written length walk, a mirror of the parser's reading, diverged from it a fourth
    /// time and let a string value's forged length through to `read_value_strs`. The data set
    /// is now walked by the parser's own token reader, so the check sees the headers the
    /// parser sees.
    #[test]
    fn string_length_the_mirror_missed_is_refused_before_allocating() {
        let (path, _) = refused_corpus_file(
            "misread_string_length.dcm",
            "(0020,000D) declares 503329024 bytes, but only 378 remain",
        );
        assert!(check_declared_lengths_of_file(&path, false).is_err());
    }

    /// Fuzz `dicom` (4.2 GB resident from a 444-byte file): the check first skipped native
    /// pixel data by its declared length, 30 bytes of OV. The parser reads an OV value as
    /// whole 8-byte numbers, 24 bytes, and reads the next header 6 bytes earlier, where it
    /// declared 4.28 GB. The check now reads every value as the parser does.
    #[test]
    fn misaligned_pixel_data_length_is_refused_before_allocating() {
        let (path, _) = refused_corpus_file(
            "misaligned_pixel_data_length.dcm",
            "(1300,1600) declares 4278201856 bytes, but only 14 remain",
        );
        assert!(check_declared_lengths_of_file(&path, false).is_err());
    }

    /// Fuzz `dicom` (an 870 MB resident set replaying the corpus): the meta group's length
    /// element (0002,0000) had a VR other than `UL`. dicom-object's meta reader checks only
    /// its tag and its length of 4, but the check took such a stream for one the reader
    /// refuses and let the reader run, which allocated a forged UID length. The check now
    /// accepts any VR there, as the reader does.
    #[test]
    fn meta_group_length_of_any_vr_is_walked() {
        let (path, _) = refused_corpus_file(
            "meta_group_length_not_ul.dcm",
            "(0002,0002) declares 875443505 bytes, but only 1 remain",
        );
        assert!(check_declared_lengths_of_file(&path, true).is_err());
    }

    /// A single-frame image whose `PixelData` is shorter than `Rows`×`Columns` asks for is
    /// refused before its volume is allocated (a 16384² frame from a 1 KB file).
    #[test]
    fn short_pixel_data_is_refused_before_allocating() {
        let mut ds = Vec::new();
        let us = |ds: &mut Vec<u8>, elem: u16, v: u16| {
            ds.extend_from_slice(&[0x28, 0x00]);
            ds.extend_from_slice(&elem.to_le_bytes());
            ds.extend_from_slice(&[b'U', b'S', 2, 0]);
            ds.extend_from_slice(&v.to_le_bytes());
        };
        us(&mut ds, 0x0002, 1); // SamplesPerPixel
        us(&mut ds, 0x0010, 16384); // Rows
        us(&mut ds, 0x0011, 16384); // Columns
        us(&mut ds, 0x0100, 16); // BitsAllocated
        us(&mut ds, 0x0101, 16); // BitsStored
        us(&mut ds, 0x0102, 15); // HighBit
        us(&mut ds, 0x0103, 0); // PixelRepresentation
        ds.extend_from_slice(&[0xE0, 0x7F, 0x10, 0x00, b'O', b'W', 0, 0, 8, 0, 0, 0]);
        ds.extend_from_slice(&[0u8; 8]);
        let e = read_bytes(&stream("1.2.840.10008.1.2.1", &ds))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("need 536870912 bytes of PixelData; it holds 8"),
            "{e}"
        );
    }

    /// A stream: preamble, meta group (explicit VR little endian unless `syntax` says
    /// otherwise), then `data_set` as given.
    fn stream(syntax: &str, data_set: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 128];
        b.extend_from_slice(b"DICM");
        let mut uid = syntax.as_bytes().to_vec();
        if uid.len() % 2 == 1 {
            uid.push(0);
        }
        b.extend_from_slice(&[2, 0, 0, 0, b'U', b'L', 4, 0]);
        b.extend_from_slice(&(8 + uid.len() as u32).to_le_bytes());
        b.extend_from_slice(&[2, 0, 0x10, 0, b'U', b'I']);
        b.extend_from_slice(&(uid.len() as u16).to_le_bytes());
        b.extend_from_slice(&uid);
        b.extend_from_slice(data_set);
        b
    }

    /// Elements after native pixel data are checked: one with a forged length is refused, a
    /// well-formed one passes, and a header-only check never gets there.
    #[test]
    fn elements_after_native_pixel_data_are_checked() {
        let mut ds = vec![
            0xE0, 0x7F, 0x10, 0x00, b'O', b'W', 0, 0, 4, 0, 0, 0, 1, 2, 3, 4,
        ];
        let good = [0xFC, 0xFF, 0xFC, 0xFF, b'O', b'B', 0, 0, 2, 0, 0, 0, 0, 0];
        let forged = [
            0xFC, 0xFF, 0xFC, 0xFF, b'O', b'B', 0, 0, 0, 0, 0xFF, 0x7F, 0, 0,
        ];
        let mut ok = ds.clone();
        ok.extend_from_slice(&good);
        check_declared_lengths(&stream("1.2.840.10008.1.2.1", &ok), false, "ok").unwrap();
        ds.extend_from_slice(&forged);
        let bytes = stream("1.2.840.10008.1.2.1", &ds);
        let e = check_declared_lengths(&bytes, false, "x")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("(FFFC,FFFC) declares 2147418112 bytes, but only 2 remain"),
            "{e}"
        );
        // A header-only read stops at the pixel data and never reaches it.
        check_declared_lengths(&bytes, true, "x").unwrap();
        // The same through a file.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("after_pixels.dcm");
        std::fs::write(&path, &bytes).unwrap();
        assert!(check_declared_lengths_of_file(&path, false).is_err());
        check_declared_lengths_of_file(&path, true).unwrap();
    }

    /// A deflated data set is walked inflated: a forged length in it is checked against the
    /// inflated bytes, not the compressed ones.
    #[test]
    fn deflated_data_set_is_checked_inflated() {
        use std::io::Write as _;
        let deflate = |raw: &[u8]| {
            let mut z = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
            z.write_all(raw).unwrap();
            z.finish().unwrap()
        };
        // (0010,0010) PN, 4 bytes; then (0009,1010) OB declaring 1000 bytes where 8 follow.
        let mut raw = vec![0x10, 0, 0x10, 0, b'P', b'N', 4, 0, b'A', b'^', b'B', b' '];
        raw.extend_from_slice(&[0x09, 0, 0x10, 0x10, b'O', b'B', 0, 0, 0xE8, 0x03, 0, 0]);
        raw.extend_from_slice(&[0u8; 1000]);
        let deflated = "1.2.840.10008.1.2.1.99";
        // Whole: 1000 bytes follow when inflated, though far fewer compressed.
        let whole = stream(deflated, &deflate(&raw));
        assert!(whole.len() < 400, "{}", whole.len());
        check_declared_lengths(&whole, false, "whole").unwrap();
        raw.truncate(raw.len() - 992);
        let e = check_declared_lengths(&stream(deflated, &deflate(&raw)), false, "x")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("(0009,1010) declares 1000 bytes, but only 8 remain"),
            "{e}"
        );
    }

    /// Fuzz `dicom` (oom-cc4cec7e…): a 998-byte file whose ImagePositionPatient declares a
    /// 4.1 GB value made the parser allocate and zero that much (4 GB resident) before
    /// failing. Declared lengths are now checked against the bytes that remain first.
    #[test]
    fn forged_value_length_is_refused_before_allocating() {
        let (path, _) = refused_corpus_file(
            "forged_value_length.dcm",
            "(0020,0032) declares 4110417936 bytes",
        );
        // The file path refuses it too, before the parser.
        assert!(check_declared_lengths_of_file(&path, false).is_err());
        assert!(check_declared_lengths_of_file(&path, true).is_err());
        // Real files pass the walk, through to their pixel data.
        for name in ["pydicom_rtdose.dcm", "pydicom_enhanced_ct.dcm"] {
            let (p, b) = corpus_file(name);
            check_declared_lengths_of_file(&p, false).unwrap();
            // Cut into the pixel data: the declared length no longer fits.
            let cut = &b[..b.len() - 10];
            let e = check_declared_lengths(cut, false, name).unwrap_err();
            assert!(e.to_string().contains("(7FE0,0010)"), "{name}: {e}");
        }
    }
}
