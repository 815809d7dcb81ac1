//! OpenIGTLink messages: header fields, metadata, and the bodies mocomp understands.

use crate::name::{DeviceName, Name, NameError, TypeName};
use crate::timestamp::Timestamp;
use mocomp_geom::nalgebra::{Isometry3, Matrix4};
use mocomp_geom::{GeomError, iso_from_matrix_mm, matrix_mm_from_iso};

/// IANA MIBenum of US-ASCII (the default text encoding).
pub const ENCODING_US_ASCII: u16 = 3;
/// IANA MIBenum of UTF-8.
pub const ENCODING_UTF8: u16 = 106;

/// One metadata entry (header version 2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetaEntry {
    /// Key (UTF-8).
    pub key: String,
    /// Value encoding (IANA MIBenum: 3 US-ASCII, 106 UTF-8).
    pub encoding: u16,
    /// Value bytes.
    pub value: Vec<u8>,
}

impl MetaEntry {
    /// A US-ASCII entry (UTF-8 when the value is not ASCII).
    pub fn text(key: &str, value: &str) -> Self {
        Self {
            key: key.to_string(),
            encoding: if value.is_ascii() {
                ENCODING_US_ASCII
            } else {
                ENCODING_UTF8
            },
            value: value.as_bytes().to_vec(),
        }
    }

    /// The value as text, when it is.
    pub fn value_str(&self) -> Option<&str> {
        std::str::from_utf8(&self.value).ok()
    }
}

/// One tool of a TDATA message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TDataElement {
    /// Tool name (20 bytes).
    pub name: DeviceName,
    /// Instrument type: 1 tracker, 2 6D, 3 3D, 4 5D.
    pub kind: u8,
    /// The tool's matrix in TRANSFORM order (see [`Body::Transform`]).
    pub matrix: [f32; 12],
}

/// A STATUS body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Status {
    /// Status code (1 OK, 4 not found, 12 illegal/unknown instruction, …).
    pub code: u16,
    /// Device-specific sub-code.
    pub subcode: i64,
    /// Error name (20 bytes).
    pub error_name: Name<20>,
    /// Status text.
    pub message: String,
}

/// Status codes used by mocomp.
pub mod status_code {
    /// OK.
    pub const OK: u16 = 1;
    /// Not found (a GET_ for something not available).
    pub const NOT_FOUND: u16 = 4;
    /// Illegal or unknown instruction (an unknown query).
    pub const UNKNOWN_INSTRUCTION: u16 = 12;
}

/// A message body.
#[derive(Debug, Clone, PartialEq)]
pub enum Body {
    /// TRANSFORM: 12 floats, column-major: R11 R21 R31, R12 R22 R32, R13 R23 R33, then the
    /// translation (mm). Affine (non-rigid) values are kept as sent.
    Transform([f32; 12]),
    /// POSITION: position (mm) and quaternion `x, y, z, w` (3-element and position-only forms
    /// are read too, with the missing parts 0 / identity).
    Position {
        /// X, Y, Z, mm.
        position: [f32; 3],
        /// Quaternion x, y, z, w.
        quaternion: [f32; 4],
    },
    /// TDATA: several tools in one message.
    TData(Vec<TDataElement>),
    /// STATUS.
    Status(Status),
    /// STRING: encoding (MIBenum) and bytes.
    String {
        /// Encoding.
        encoding: u16,
        /// The text bytes.
        text: Vec<u8>,
    },
    /// STT_TDATA: start streaming TDATA.
    StartTData {
        /// Minimum interval between frames, ms (0 = as fast as possible).
        resolution_ms: u32,
        /// Coordinate system name (32 bytes).
        coordinate: Name<32>,
    },
    /// RTS_TDATA: the reply to STT_/STP_TDATA.
    RtsTData {
        /// 0 success, 1 error.
        status: u8,
    },
    /// Any other GET_/STT_/STP_/RTS_ message; the type name says what; content kept raw.
    Query(Vec<u8>),
    /// A type mocomp does not read; its body was skipped (after the CRC check).
    Unknown {
        /// Content size, bytes.
        size: usize,
    },
}

/// A complete message.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// Header version: 1 (no extended header) or 2 (extended header and metadata).
    pub header_version: u16,
    /// Type name (e.g. "TRANSFORM").
    pub type_name: TypeName,
    /// Device name (e.g. "HeadToTracker").
    pub device: DeviceName,
    /// Timestamp (0 = unused).
    pub timestamp: Timestamp,
    /// Message id (header version 2).
    pub message_id: u32,
    /// Metadata (header version 2).
    pub metadata: Vec<MetaEntry>,
    /// The body.
    pub body: Body,
}

/// What a query asks about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueryTarget {
    /// TRANSFORM (spelled `TRANS` by the C++ library, `TRANSFOR` in the protocol summary).
    Transform,
    /// TDATA.
    TData,
    /// STATUS.
    Status,
    /// Anything else.
    Other,
}

/// The kind of query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueryKind {
    /// GET_: one message, please.
    Get,
    /// STT_: start a stream.
    Start,
    /// STP_: stop it.
    Stop,
    /// RTS_: a reply.
    Reply,
}

impl Message {
    /// A message with header version 1, no timestamp, no metadata.
    pub fn new(type_name: &str, device: &str, body: Body) -> Result<Self, NameError> {
        Ok(Self {
            header_version: 1,
            type_name: TypeName::new(type_name)?,
            device: DeviceName::new(device)?,
            timestamp: Timestamp::NONE,
            message_id: 0,
            metadata: Vec::new(),
            body,
        })
    }

    /// A TRANSFORM carrying a rigid transform (metres inside, millimetres on the wire).
    pub fn transform(
        device: &str,
        pose: &Isometry3<f64>,
        timestamp: Timestamp,
    ) -> Result<Self, NameError> {
        let mut m = Self::new("TRANSFORM", device, Body::Transform(transform_floats(pose)))?;
        m.timestamp = timestamp;
        Ok(m)
    }

    /// The same message with header version 2 and these metadata entries.
    pub fn with_metadata(mut self, metadata: Vec<MetaEntry>) -> Self {
        self.header_version = 2;
        self.metadata = metadata;
        self
    }

    /// A metadata value by key, as text.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|e| e.key == key)
            .and_then(MetaEntry::value_str)
    }

    /// The query this message is, if its type is GET_/STT_/STP_/RTS_.
    pub fn query(&self) -> Option<(QueryKind, QueryTarget)> {
        query_of(self.type_name.as_str())
    }
}

/// Classifies a query type name; accepts both spellings of the transform query.
pub fn query_of(type_name: &str) -> Option<(QueryKind, QueryTarget)> {
    let (kind, rest) = if let Some(r) = type_name.strip_prefix("GET_") {
        (QueryKind::Get, r)
    } else if let Some(r) = type_name.strip_prefix("STT_") {
        (QueryKind::Start, r)
    } else if let Some(r) = type_name.strip_prefix("STP_") {
        (QueryKind::Stop, r)
    } else if let Some(r) = type_name.strip_prefix("RTS_") {
        (QueryKind::Reply, r)
    } else {
        return None;
    };
    let target = match rest {
        "TRANS" | "TRANSFOR" | "TRANSFORM" => QueryTarget::Transform,
        "TDATA" => QueryTarget::TData,
        "STATUS" => QueryTarget::Status,
        _ => QueryTarget::Other,
    };
    Some((kind, target))
}

/// The 12 TRANSFORM floats of a rigid transform (translation in mm).
pub fn transform_floats(pose: &Isometry3<f64>) -> [f32; 12] {
    let m = matrix_mm_from_iso(pose);
    let mut out = [0f32; 12];
    for c in 0..4 {
        for r in 0..3 {
            out[3 * c + r] = m[(r, c)] as f32;
        }
    }
    out
}

/// The 4×4 homogeneous matrix (translation in mm) of TRANSFORM floats.
pub fn matrix_mm(f: &[f32; 12]) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    for c in 0..4 {
        for r in 0..3 {
            m[(r, c)] = f64::from(f[3 * c + r]);
        }
    }
    m
}

/// Float precision of TRANSFORM matrices: the tolerance for accepting their rotation as rigid.
pub const F32_RIGID_TOLERANCE: f64 = 1e-4;

/// The rigid transform (metres) of TRANSFORM floats, or why they are not rigid.
pub fn pose_of(f: &[f32; 12]) -> Result<Isometry3<f64>, GeomError> {
    iso_from_matrix_mm(&matrix_mm(f), F32_RIGID_TOLERANCE)
}
