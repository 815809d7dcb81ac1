//! Encoding and decoding OpenIGTLink messages, without I/O.
//!
//! Header (58 bytes, big-endian): version u16, type char[12], device char[20], timestamp u64,
//! body size u64, CRC-64/ECMA-182 of the body u64. With header version 2 the body is
//! `[extended header 12 B][content][metadata header][metadata]`; the extended header holds its own
//! size, the metadata header size (`2 + 8·N`, including the count), the metadata size and a
//! message id.

use crate::message::{Body, Message, MetaEntry, Status, TDataElement};
use crate::name::{DeviceName, Name, TypeName};
use crate::timestamp::Timestamp;
use crc::{CRC_64_ECMA_182, Crc, Table};

/// Header size, bytes.
pub const HEADER_SIZE: usize = 58;
/// Extended header size (header version 2), bytes.
pub const EXT_HEADER_SIZE: usize = 12;
/// Default limit on a body's size: anything larger is refused before allocating (a hostile or
/// corrupt header cannot make us allocate gigabytes).
pub const DEFAULT_MAX_BODY: u64 = 16 * 1024 * 1024;
const TDATA_ELEMENT: usize = 70;

/// CRC-64/ECMA-182 (MSB-first, polynomial 0x42F0E1EBA9EA3693, init 0, no final XOR), as
/// OpenIGTLink's `igtl_util.c` computes it; slice-by-16 tables.
pub static CRC64: Crc<u64, Table<16>> = Crc::<u64, Table<16>>::new(&CRC_64_ECMA_182);

/// What can go wrong decoding. [`DecodeError::is_fatal`] tells whether the stream can go on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// A header version other than 1 or 2: the bytes are not OpenIGTLink (or are out of step).
    #[error(
        "header version {version} (expected 1 or 2): not an OpenIGTLink stream, or out of step"
    )]
    HeaderVersion {
        /// The version found.
        version: u16,
    },
    /// A type or device name that is not ASCII.
    #[error("{field} name is not ASCII: not an OpenIGTLink stream, or out of step")]
    HeaderName {
        /// "type" or "device".
        field: &'static str,
    },
    /// A body larger than the limit.
    #[error(
        "{type_name} message from {device:?} announces a {size}-byte body, more than the {limit}-byte limit"
    )]
    BodyTooLarge {
        /// Type name.
        type_name: String,
        /// Device name.
        device: String,
        /// Announced size.
        size: u64,
        /// The limit.
        limit: u64,
    },
    /// The body's CRC does not match the header's: the message is dropped.
    #[error(
        "CRC mismatch in {type_name} message from {device:?}: header {expected:#018x}, body {computed:#018x}; message dropped"
    )]
    Crc {
        /// Type name.
        type_name: String,
        /// Device name.
        device: String,
        /// CRC in the header.
        expected: u64,
        /// CRC of the body received.
        computed: u64,
    },
    /// A body that does not have the layout its type requires: the message is dropped.
    #[error("malformed {type_name} message from {device:?} at body byte {offset}: {reason}")]
    Malformed {
        /// Type name.
        type_name: String,
        /// Device name.
        device: String,
        /// Offset in the body where the problem is.
        offset: usize,
        /// What is wrong.
        reason: String,
    },
}

impl DecodeError {
    /// True when the stream cannot be trusted any more (the header itself is bad): the
    /// connection should be dropped. CRC and layout errors only drop the one message.
    pub fn is_fatal(&self) -> bool {
        matches!(
            self,
            DecodeError::HeaderVersion { .. }
                | DecodeError::HeaderName { .. }
                | DecodeError::BodyTooLarge { .. }
        )
    }
}

/// A decoded header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Header version.
    pub version: u16,
    /// Type name.
    pub type_name: TypeName,
    /// Device name.
    pub device: DeviceName,
    /// Timestamp.
    pub timestamp: Timestamp,
    /// Body size, bytes.
    pub body_size: u64,
    /// CRC of the body.
    pub crc: u64,
}

fn be_u16(b: &[u8], o: usize) -> u16 {
    u16::from_be_bytes([b[o], b[o + 1]])
}
fn be_u32(b: &[u8], o: usize) -> u32 {
    u32::from_be_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}
fn be_u64(b: &[u8], o: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[o..o + 8]);
    u64::from_be_bytes(a)
}
fn be_f32(b: &[u8], o: usize) -> f32 {
    f32::from_bits(be_u32(b, o))
}

/// Decodes the 58-byte header (no limit check).
pub fn decode_header(b: &[u8; HEADER_SIZE]) -> Result<Header, DecodeError> {
    let version = be_u16(b, 0);
    if version != 1 && version != 2 {
        return Err(DecodeError::HeaderVersion { version });
    }
    let mut t = [0u8; 12];
    t.copy_from_slice(&b[2..14]);
    let mut d = [0u8; 20];
    d.copy_from_slice(&b[14..34]);
    Ok(Header {
        version,
        type_name: TypeName::from_wire(&t).ok_or(DecodeError::HeaderName { field: "type" })?,
        device: DeviceName::from_wire(&d).ok_or(DecodeError::HeaderName { field: "device" })?,
        timestamp: Timestamp(be_u64(b, 34)),
        body_size: be_u64(b, 42),
        crc: be_u64(b, 50),
    })
}

fn malformed(h: &Header, offset: usize, reason: impl Into<String>) -> DecodeError {
    DecodeError::Malformed {
        type_name: h.type_name.to_string(),
        device: h.device.to_string(),
        offset,
        reason: reason.into(),
    }
}

/// Decodes a body (CRC already checked) into a message.
pub fn decode_body(h: &Header, body: &[u8]) -> Result<Message, DecodeError> {
    let mut message_id = 0;
    let mut metadata = Vec::new();
    let mut content = body;
    let mut content_offset = 0;
    if h.version == 2 {
        if body.len() < EXT_HEADER_SIZE {
            return Err(malformed(
                h,
                0,
                format!(
                    "{} bytes, shorter than the 12-byte extended header",
                    body.len()
                ),
            ));
        }
        let ext = usize::from(be_u16(body, 0));
        let meta_header = usize::from(be_u16(body, 2));
        let meta_size = be_u32(body, 4) as usize;
        message_id = be_u32(body, 8);
        if ext < EXT_HEADER_SIZE || ext > body.len() {
            return Err(malformed(h, 0, format!("extended header size {ext}")));
        }
        let tail = meta_header.checked_add(meta_size).filter(|t| ext + t <= body.len()).ok_or_else(|| {
            malformed(h, 2, format!("metadata header {meta_header} + metadata {meta_size} bytes do not fit the body"))
        })?;
        let meta_start = body.len() - tail;
        if meta_header > 0 {
            let mh = &body[meta_start..meta_start + meta_header];
            let count = usize::from(be_u16(mh, 0));
            if meta_header != 2 + 8 * count {
                return Err(malformed(
                    h,
                    meta_start,
                    format!(
                        "metadata header size {meta_header} for {count} entries (expected {})",
                        2 + 8 * count
                    ),
                ));
            }
            let mut pos = meta_start + meta_header;
            let end = body.len();
            for i in 0..count {
                let o = 2 + 8 * i;
                let key_size = usize::from(be_u16(mh, o));
                let encoding = be_u16(mh, o + 2);
                let value_size = be_u32(mh, o + 4) as usize;
                if pos + key_size + value_size > end {
                    return Err(malformed(
                        h,
                        pos,
                        format!("metadata entry {i} runs past the body"),
                    ));
                }
                let key = std::str::from_utf8(&body[pos..pos + key_size])
                    .map_err(|_| malformed(h, pos, format!("metadata key {i} is not UTF-8")))?
                    .to_string();
                pos += key_size;
                let value = body[pos..pos + value_size].to_vec();
                pos += value_size;
                metadata.push(MetaEntry {
                    key,
                    encoding,
                    value,
                });
            }
            if pos != end {
                return Err(malformed(
                    h,
                    pos,
                    format!(
                        "metadata sizes add up to {} bytes, not {meta_size}",
                        pos - meta_start - meta_header
                    ),
                ));
            }
        } else if meta_size != 0 {
            return Err(malformed(h, 4, "metadata without a metadata header"));
        }
        content = &body[ext..meta_start];
        content_offset = ext;
    }
    let body = decode_content(h, content, content_offset)?;
    Ok(Message {
        header_version: h.version,
        type_name: h.type_name,
        device: h.device,
        timestamp: h.timestamp,
        message_id,
        metadata,
        body,
    })
}

fn floats12(c: &[u8], o: usize) -> [f32; 12] {
    std::array::from_fn(|k| be_f32(c, o + 4 * k))
}

fn decode_content(h: &Header, c: &[u8], base: usize) -> Result<Body, DecodeError> {
    let t = h.type_name.as_str();
    let need = |n: usize| -> Result<(), DecodeError> {
        if c.len() == n {
            Ok(())
        } else {
            Err(malformed(
                h,
                base,
                format!("{} content bytes, expected {n}", c.len()),
            ))
        }
    };
    Ok(match t {
        "TRANSFORM" => {
            need(48)?;
            Body::Transform(floats12(c, 0))
        }
        "POSITION" => {
            let q = match c.len() {
                12 => [0.0, 0.0, 0.0, 1.0],
                24 => {
                    let (x, y, z) = (be_f32(c, 12), be_f32(c, 16), be_f32(c, 20));
                    [x, y, z, (1.0 - x * x - y * y - z * z).max(0.0).sqrt()]
                }
                28 => [be_f32(c, 12), be_f32(c, 16), be_f32(c, 20), be_f32(c, 24)],
                n => {
                    return Err(malformed(
                        h,
                        base,
                        format!("{n} content bytes, expected 12, 24 or 28"),
                    ));
                }
            };
            Body::Position {
                position: [be_f32(c, 0), be_f32(c, 4), be_f32(c, 8)],
                quaternion: q,
            }
        }
        "TDATA" => {
            if !c.len().is_multiple_of(TDATA_ELEMENT) {
                return Err(malformed(
                    h,
                    base,
                    format!(
                        "{} content bytes, not a multiple of {TDATA_ELEMENT}",
                        c.len()
                    ),
                ));
            }
            let mut tools = Vec::with_capacity(c.len() / TDATA_ELEMENT);
            for (i, e) in c.chunks_exact(TDATA_ELEMENT).enumerate() {
                let mut n = [0u8; 20];
                n.copy_from_slice(&e[0..20]);
                let name = DeviceName::from_wire(&n).ok_or_else(|| {
                    malformed(
                        h,
                        base + i * TDATA_ELEMENT,
                        format!("tool {i} name is not ASCII"),
                    )
                })?;
                tools.push(TDataElement {
                    name,
                    kind: e[20],
                    matrix: floats12(e, 22),
                });
            }
            Body::TData(tools)
        }
        "STATUS" => {
            if c.len() < 30 {
                return Err(malformed(
                    h,
                    base,
                    format!("{} content bytes, at least 30 expected", c.len()),
                ));
            }
            let mut n = [0u8; 20];
            n.copy_from_slice(&c[10..30]);
            let error_name = Name::<20>::from_wire(&n)
                .ok_or_else(|| malformed(h, base + 10, "error name is not ASCII"))?;
            let text = &c[30..];
            let text = &text[..text.iter().position(|&b| b == 0).unwrap_or(text.len())];
            Body::Status(Status {
                code: be_u16(c, 0),
                subcode: be_u64(c, 2) as i64,
                error_name,
                message: String::from_utf8_lossy(text).into_owned(),
            })
        }
        "STRING" => {
            if c.len() < 4 {
                return Err(malformed(
                    h,
                    base,
                    format!("{} content bytes, at least 4 expected", c.len()),
                ));
            }
            let len = usize::from(be_u16(c, 2));
            if 4 + len != c.len() {
                return Err(malformed(
                    h,
                    base + 2,
                    format!("string length {len} but {} bytes follow", c.len() - 4),
                ));
            }
            Body::String {
                encoding: be_u16(c, 0),
                text: c[4..].to_vec(),
            }
        }
        "STT_TDATA" => {
            if c.is_empty() {
                Body::StartTData {
                    resolution_ms: 0,
                    coordinate: Name::<32>::empty(),
                }
            } else {
                need(36)?;
                let mut n = [0u8; 32];
                n.copy_from_slice(&c[4..36]);
                let coordinate = Name::<32>::from_wire(&n)
                    .ok_or_else(|| malformed(h, base + 4, "coordinate name is not ASCII"))?;
                Body::StartTData {
                    resolution_ms: be_u32(c, 0),
                    coordinate,
                }
            }
        }
        "RTS_TDATA" => {
            need(1)?;
            Body::RtsTData { status: c[0] }
        }
        _ if crate::message::query_of(t).is_some() => Body::Query(c.to_vec()),
        _ => Body::Unknown { size: c.len() },
    })
}

/// Decodes one message from the front of `buf`. `Ok(None)`: more bytes are needed. `Ok(Some((m,
/// n)))`: a message and the bytes it used. A non-fatal error also consumed its message's bytes;
/// see [`Decoder`] for a stream.
pub fn decode(buf: &[u8], max_body: u64) -> Result<Option<(Message, usize)>, (DecodeError, usize)> {
    if buf.len() < HEADER_SIZE {
        return Ok(None);
    }
    let mut hb = [0u8; HEADER_SIZE];
    hb.copy_from_slice(&buf[..HEADER_SIZE]);
    let h = decode_header(&hb).map_err(|e| (e, 0))?;
    if h.body_size > max_body {
        return Err((
            DecodeError::BodyTooLarge {
                type_name: h.type_name.to_string(),
                device: h.device.to_string(),
                size: h.body_size,
                limit: max_body,
            },
            0,
        ));
    }
    let total = HEADER_SIZE + h.body_size as usize;
    if buf.len() < total {
        return Ok(None);
    }
    let body = &buf[HEADER_SIZE..total];
    let computed = CRC64.checksum(body);
    if computed != h.crc {
        return Err((
            DecodeError::Crc {
                type_name: h.type_name.to_string(),
                device: h.device.to_string(),
                expected: h.crc,
                computed,
            },
            total,
        ));
    }
    match decode_body(&h, body) {
        Ok(m) => Ok(Some((m, total))),
        Err(e) => Err((e, total)),
    }
}

/// A streaming decoder: feed it bytes as they arrive, in pieces of any size; take messages out.
/// After a fatal error it refuses further input until [`Decoder::reset`].
#[derive(Debug)]
pub struct Decoder {
    buf: Vec<u8>,
    start: usize,
    max_body: u64,
    failed: bool,
}

impl Decoder {
    /// A decoder refusing bodies larger than `max_body` bytes.
    pub fn new(max_body: u64) -> Self {
        Self {
            buf: Vec::with_capacity(64 * 1024),
            start: 0,
            max_body,
            failed: false,
        }
    }

    /// Appends received bytes.
    pub fn feed(&mut self, data: &[u8]) {
        if self.start > 0 && self.start >= self.buf.len() / 2 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(data);
    }

    /// Bytes waiting (part of a message not complete yet).
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Forgets everything (after a reconnect).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.start = 0;
        self.failed = false;
    }

    /// The next message, an error for one message (the stream goes on), a fatal error (the stream
    /// is broken), or `None` when more bytes are needed.
    pub fn next_message(&mut self) -> Option<Result<Message, DecodeError>> {
        if self.failed {
            return None;
        }
        match decode(&self.buf[self.start..], self.max_body) {
            Ok(None) => None,
            Ok(Some((m, n))) => {
                self.start += n;
                Some(Ok(m))
            }
            Err((e, n)) => {
                if e.is_fatal() {
                    self.failed = true;
                } else {
                    self.start += n;
                }
                Some(Err(e))
            }
        }
    }
}

fn put_name<const N: usize>(out: &mut Vec<u8>, n: &Name<N>) {
    out.extend_from_slice(n.wire());
}

fn put_floats(out: &mut Vec<u8>, f: &[f32]) {
    for v in f {
        out.extend_from_slice(&v.to_be_bytes());
    }
}

fn encode_content(body: &Body, out: &mut Vec<u8>) {
    match body {
        Body::Transform(f) => put_floats(out, f),
        Body::Position {
            position,
            quaternion,
        } => {
            put_floats(out, position);
            put_floats(out, quaternion);
        }
        Body::TData(tools) => {
            for t in tools {
                put_name(out, &t.name);
                out.push(t.kind);
                out.push(0);
                put_floats(out, &t.matrix);
            }
        }
        Body::Status(s) => {
            out.extend_from_slice(&s.code.to_be_bytes());
            out.extend_from_slice(&s.subcode.to_be_bytes());
            put_name(out, &s.error_name);
            out.extend_from_slice(s.message.as_bytes());
            out.push(0);
        }
        Body::String { encoding, text } => {
            out.extend_from_slice(&encoding.to_be_bytes());
            out.extend_from_slice(&(text.len().min(usize::from(u16::MAX)) as u16).to_be_bytes());
            out.extend_from_slice(&text[..text.len().min(usize::from(u16::MAX))]);
        }
        Body::StartTData {
            resolution_ms,
            coordinate,
        } => {
            out.extend_from_slice(&resolution_ms.to_be_bytes());
            put_name(out, coordinate);
        }
        Body::RtsTData { status } => out.push(*status),
        Body::Query(c) => out.extend_from_slice(c),
        Body::Unknown { size } => out.resize(out.len() + size, 0),
    }
}

/// Encodes a message (header, extended header and metadata for header version 2, CRC) and appends
/// it to `out`.
pub fn encode_into(m: &Message, out: &mut Vec<u8>) {
    let start = out.len();
    out.resize(start + HEADER_SIZE, 0);
    let body_start = out.len();
    if m.header_version >= 2 {
        // Extended header: sizes filled in below.
        out.resize(body_start + EXT_HEADER_SIZE, 0);
    }
    encode_content(&m.body, out);
    if m.header_version >= 2 {
        let meta_header = 2 + 8 * m.metadata.len();
        let meta_size: usize = m.metadata.iter().map(|e| e.key.len() + e.value.len()).sum();
        out.extend_from_slice(&(m.metadata.len() as u16).to_be_bytes());
        for e in &m.metadata {
            out.extend_from_slice(&(e.key.len() as u16).to_be_bytes());
            out.extend_from_slice(&e.encoding.to_be_bytes());
            out.extend_from_slice(&(e.value.len() as u32).to_be_bytes());
        }
        for e in &m.metadata {
            out.extend_from_slice(e.key.as_bytes());
            out.extend_from_slice(&e.value);
        }
        let ext = &mut out[body_start..body_start + EXT_HEADER_SIZE];
        ext[0..2].copy_from_slice(&(EXT_HEADER_SIZE as u16).to_be_bytes());
        ext[2..4].copy_from_slice(&(meta_header as u16).to_be_bytes());
        ext[4..8].copy_from_slice(&(meta_size as u32).to_be_bytes());
        ext[8..12].copy_from_slice(&m.message_id.to_be_bytes());
    }
    let body_size = (out.len() - body_start) as u64;
    let crc = CRC64.checksum(&out[body_start..]);
    let h = &mut out[start..body_start];
    h[0..2].copy_from_slice(&m.header_version.clamp(1, 2).to_be_bytes());
    h[2..14].copy_from_slice(m.type_name.wire());
    h[14..34].copy_from_slice(m.device.wire());
    h[34..42].copy_from_slice(&m.timestamp.0.to_be_bytes());
    h[42..50].copy_from_slice(&body_size.to_be_bytes());
    h[50..58].copy_from_slice(&crc.to_be_bytes());
}

/// Encodes a message into a new buffer.
pub fn encode(m: &Message) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_SIZE + 128);
    encode_into(m, &mut out);
    out
}
