//! The studio's wire format: one binary WebSocket message per frame (see `PROTOCOL.md` in
//! this crate for the full schema and every message kind).
//!
//! A frame is, little-endian:
//!
//! | bytes | field |
//! | --- | --- |
//! | 0‥4 | magic `VMST` |
//! | 4‥6 | `u16` protocol version ([`VERSION`]) |
//! | 6‥8 | `u16` message kind ([`Kind`]) |
//! | 8‥12 | `u32` request number (the client's; echoed in replies, 0 for pushes) |
//! | 12‥16 | `u32` header length `h` |
//! | 16‥16+h | header: a UTF-8 JSON object (the message's fields) |
//! | 16+h‥ | payload: raw little-endian arrays whose layout the header states |
//!
//! JSON carries the small structured fields (ids, names, boxes, options) in a form that is
//! easy to extend and to read in a browser; the payload carries bulk arrays (slices, volumes,
//! vertex buffers) without conversion, ready for `Float32Array` and WebGL uploads.

use serde_json::Value;

/// The protocol version. A frame with another version is refused with an
/// [`Kind::Error`] and the socket is closed.
pub const VERSION: u16 = 1;

/// The frame's magic bytes.
pub const MAGIC: [u8; 4] = *b"VMST";

/// Bytes before the header.
pub const PREFIX_LEN: usize = 16;

/// Largest frame a page may send (bytes). Uploads go through HTTP, so a client message is
/// small: a drag, a command, a source text.
pub const MAX_CLIENT_FRAME: usize = 1 << 20;

/// Message kinds. Client → server below 100, server → client from 100.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum Kind {
    /// Client: first message; header `{}`. Reply [`Kind::Welcome`].
    Hello = 1,
    /// Client: the object list. Reply [`Kind::Scene`].
    ListObjects = 2,
    /// Client: a slice of a volume. Reply [`Kind::Slice`].
    GetSlice = 3,
    /// Client: one move of a direct-manipulation drag (coalesced).
    Drag = 4,
    /// Client: the end of a gesture (its moves become one undo step).
    EndGesture = 5,
    /// Client: undo the last command.
    Undo = 6,
    /// Client: redo the last command undone.
    Redo = 7,
    /// Client: a volume as 8-bit texture data. Reply [`Kind::VolumeData`].
    GetVolume = 8,
    /// Client: cube-cutting proxy geometry for a view direction. Reply [`Kind::Proxy`].
    GetProxy = 9,
    /// Client: a mesh's vertex and index buffers. Reply [`Kind::MeshData`].
    GetMesh = 10,
    /// Client: a lattice's control points. Reply [`Kind::LatticeData`].
    GetLattice = 11,
    /// Client: move control points of a lattice (coalesced per gesture).
    MoveControlPoints = 12,
    /// Client: set up a built-in workflow (a phantom, a lattice and the derived objects).
    Setup = 13,
    /// Client: a point mapped by a map. Reply [`Kind::Probed`].
    Probe = 14,
    /// Client: a transfer function's table. Reply [`Kind::Transfer`].
    GetTransfer = 15,
    /// Client: any scene command as JSON (see `PROTOCOL.md`).
    Command = 16,
    /// Client: a folder listing under a root. Reply [`Kind::Listing`].
    ListDir = 17,
    /// Client: open a file under a root as a new object.
    OpenFile = 18,
    /// Client: save the scene as a project file under a root.
    SaveScene = 19,
    /// Client: load a project file under a root (replaces the scene).
    LoadScene = 20,
    /// Client: export an object to a file under a root.
    Export = 21,
    /// Client: the Jacobian determinant of a map on a slice of a volume's grid. Reply
    /// [`Kind::Slice`].
    GetJacobian = 22,
    /// Client: stop the job of one of the page's requests (running or still queued). The job
    /// answers with [`Kind::Error`] `{cancelled: true}` and changes nothing.
    Cancel = 23,
    /// Server: the reply to [`Kind::Hello`].
    Welcome = 100,
    /// Server: the object list and history depths.
    Scene = 101,
    /// Server: what a command changed (pushed to every page).
    Changed = 102,
    /// Server: a slice (payload `f32` values).
    Slice = 103,
    /// Server: an error.
    Error = 104,
    /// Server: volume texture data (payload `u8`).
    VolumeData = 105,
    /// Server: proxy geometry (payload `f32` vertices then `u32` indices).
    Proxy = 106,
    /// Server: a mesh (payload `f32` positions, `f32` normals, `u32` indices).
    MeshData = 107,
    /// Server: lattice control points (payload `f32` xyz).
    LatticeData = 108,
    /// Server: a probed point.
    Probed = 109,
    /// Server: a transfer table (payload 256 × RGBA `u8`).
    Transfer = 110,
    /// Server: a folder listing.
    Listing = 111,
    /// Server: a request done (save, export, …).
    Done = 112,
    /// Server: how far the long job of one of the page's requests has got (pushed to that
    /// page only, at most every [`crate::jobs::PROGRESS_INTERVAL`], from
    /// [`crate::jobs::PROGRESS_DELAY`] after the job started).
    Progress = 113,
}

impl Kind {
    /// The kind of a number, if known.
    #[must_use]
    pub fn from_u16(v: u16) -> Option<Self> {
        use Kind::*;
        Some(match v {
            1 => Hello,
            2 => ListObjects,
            3 => GetSlice,
            4 => Drag,
            5 => EndGesture,
            6 => Undo,
            7 => Redo,
            8 => GetVolume,
            9 => GetProxy,
            10 => GetMesh,
            11 => GetLattice,
            12 => MoveControlPoints,
            13 => Setup,
            14 => Probe,
            15 => GetTransfer,
            16 => Command,
            17 => ListDir,
            18 => OpenFile,
            19 => SaveScene,
            20 => LoadScene,
            21 => Export,
            22 => GetJacobian,
            23 => Cancel,
            100 => Welcome,
            101 => Scene,
            102 => Changed,
            103 => Slice,
            104 => Error,
            105 => VolumeData,
            106 => Proxy,
            107 => MeshData,
            108 => LatticeData,
            109 => Probed,
            110 => Transfer,
            111 => Listing,
            112 => Done,
            113 => Progress,
            _ => return None,
        })
    }
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// The message kind.
    pub kind: Kind,
    /// The request number (0 for server pushes).
    pub request: u32,
    /// The header fields (a JSON object).
    pub header: Value,
    /// The payload bytes.
    pub payload: Vec<u8>,
}

/// Why a frame cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// Shorter than its prefix or its stated header.
    #[error("frame of {0} bytes is truncated")]
    Truncated(usize),
    /// Not a volmorph studio frame.
    #[error("frame does not start with the magic bytes VMST")]
    Magic,
    /// Another protocol version.
    #[error("protocol version {found} is not supported (this server speaks version {VERSION})")]
    Version {
        /// The frame's version.
        found: u16,
    },
    /// An unknown message kind.
    #[error("unknown message kind {0}")]
    Kind(u16),
    /// The header is not a JSON object.
    #[error("frame header is not a JSON object: {0}")]
    Header(String),
    /// Larger than [`MAX_CLIENT_FRAME`].
    #[error("frame of {0} bytes exceeds the limit of {MAX_CLIENT_FRAME} bytes")]
    TooLarge(usize),
}

impl Frame {
    /// A frame with no payload.
    #[must_use]
    pub fn new(kind: Kind, request: u32, header: Value) -> Self {
        Self {
            kind,
            request,
            header,
            payload: Vec::new(),
        }
    }

    /// The same frame with `payload`.
    #[must_use]
    pub fn with_payload(mut self, payload: Vec<u8>) -> Self {
        self.payload = payload;
        self
    }

    /// Encode as bytes (see the [module docs](self)).
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let header = self.header.to_string();
        let mut out = Vec::with_capacity(PREFIX_LEN + header.len() + self.payload.len());
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(self.kind as u16).to_le_bytes());
        out.extend_from_slice(&self.request.to_le_bytes());
        out.extend_from_slice(
            &u32::try_from(header.len())
                .unwrap_or(u32::MAX)
                .to_le_bytes(),
        );
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&self.payload);
        out
    }

    /// Decode bytes.
    ///
    /// # Errors
    /// [`FrameError`] naming what is wrong; the version is checked before the kind, so a
    /// client of another version is told so.
    pub fn decode(bytes: &[u8]) -> Result<Self, FrameError> {
        if bytes.len() > MAX_CLIENT_FRAME {
            return Err(FrameError::TooLarge(bytes.len()));
        }
        if bytes.len() < PREFIX_LEN {
            return Err(FrameError::Truncated(bytes.len()));
        }
        if bytes[0..4] != MAGIC {
            return Err(FrameError::Magic);
        }
        let u16_at = |i: usize| u16::from_le_bytes([bytes[i], bytes[i + 1]]);
        let u32_at =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let version = u16_at(4);
        if version != VERSION {
            return Err(FrameError::Version { found: version });
        }
        let kind = Kind::from_u16(u16_at(6)).ok_or(FrameError::Kind(u16_at(6)))?;
        let request = u32_at(8);
        let h = u32_at(12) as usize;
        let end = PREFIX_LEN
            .checked_add(h)
            .filter(|e| *e <= bytes.len())
            .ok_or(FrameError::Truncated(bytes.len()))?;
        let header: Value = serde_json::from_slice(&bytes[PREFIX_LEN..end])
            .map_err(|e| FrameError::Header(e.to_string()))?;
        if !header.is_object() {
            return Err(FrameError::Header("not an object".into()));
        }
        Ok(Self {
            kind,
            request,
            header,
            payload: bytes[end..].to_vec(),
        })
    }
}

/// Little-endian bytes of `f32` values (the payload form of every float array).
#[must_use]
pub fn f32_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// Little-endian bytes of `u32` values.
#[must_use]
pub fn u32_bytes(values: impl IntoIterator<Item = u32>) -> Vec<u8> {
    values.into_iter().flat_map(u32::to_le_bytes).collect()
}

/// Read `f32` values from little-endian bytes (a trailing partial value is ignored).
#[must_use]
pub fn read_f32(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn frames_round_trip() {
        let f = Frame::new(Kind::Drag, 7, json!({"a": 1})).with_payload(vec![1, 2, 3]);
        assert_eq!(Frame::decode(&f.encode()).unwrap(), f);
    }

    #[test]
    fn other_versions_are_refused_by_number() {
        let mut b = Frame::new(Kind::Hello, 1, json!({})).encode();
        b[4] = 2;
        assert_eq!(Frame::decode(&b), Err(FrameError::Version { found: 2 }));
    }

    #[test]
    fn truncated_and_malformed_frames_are_errors() {
        let b = Frame::new(Kind::Hello, 1, json!({"x": "yyyy"})).encode();
        assert!(matches!(
            Frame::decode(&b[..20]),
            Err(FrameError::Truncated(_))
        ));
        assert_eq!(Frame::decode(&b[..3]), Err(FrameError::Truncated(3)));
        let mut m = b.clone();
        m[0] = b'X';
        assert_eq!(Frame::decode(&m), Err(FrameError::Magic));
        let mut k = b.clone();
        k[6] = 99;
        assert_eq!(Frame::decode(&k), Err(FrameError::Kind(99)));
        let mut h = Frame::new(Kind::Hello, 1, json!([1])).encode();
        assert!(matches!(Frame::decode(&h), Err(FrameError::Header(_))));
        h.truncate(PREFIX_LEN);
        h[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(Frame::decode(&h), Err(FrameError::Truncated(_))));
    }
}
