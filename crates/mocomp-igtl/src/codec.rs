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

/// A bounded reader over a message body: every read checks that the bytes are there before it
/// takes them, and an error names the body offset it stopped at. Nothing here indexes a slice.
struct Reader<'a> {
    h: &'a Header,
    rest: &'a [u8],
    /// Body offset of `rest[0]`.
    at: usize,
}

impl<'a> Reader<'a> {
    fn new(h: &'a Header, bytes: &'a [u8], at: usize) -> Self {
        Self { h, rest: bytes, at }
    }

    fn fail(&self, reason: impl Into<String>) -> DecodeError {
        malformed(self.h, self.at, reason)
    }

    fn short(&self, what: &str, needed: usize) -> DecodeError {
        self.fail(format!(
            "{what}: {needed} bytes needed, {} left",
            self.rest.len()
        ))
    }

    fn bytes(&mut self, n: usize, what: &str) -> Result<&'a [u8], DecodeError> {
        let (taken, rest) = self
            .rest
            .split_at_checked(n)
            .ok_or_else(|| self.short(what, n))?;
        self.rest = rest;
        self.at += n;
        Ok(taken)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        let taken = self.bytes(N, what)?;
        a.copy_from_slice(taken);
        Ok(a)
    }

    fn u8(&mut self, what: &str) -> Result<u8, DecodeError> {
        Ok(self.array::<1>(what)?[0])
    }
    fn u16(&mut self, what: &str) -> Result<u16, DecodeError> {
        Ok(u16::from_be_bytes(self.array(what)?))
    }
    fn u32(&mut self, what: &str) -> Result<u32, DecodeError> {
        Ok(u32::from_be_bytes(self.array(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64, DecodeError> {
        Ok(u64::from_be_bytes(self.array(what)?))
    }
    fn f32(&mut self, what: &str) -> Result<f32, DecodeError> {
        Ok(f32::from_bits(self.u32(what)?))
    }
    fn floats<const N: usize>(&mut self, what: &str) -> Result<[f32; N], DecodeError> {
        let mut f = [0f32; N];
        for v in &mut f {
            *v = self.f32(what)?;
        }
        Ok(f)
    }

    /// The rest, which must be empty.
    fn end(&self, what: &str) -> Result<(), DecodeError> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(self.fail(format!("{} bytes after the {what}", self.rest.len())))
        }
    }
}

/// Decodes the 58-byte header (no limit check).
pub fn decode_header(b: &[u8; HEADER_SIZE]) -> Result<Header, DecodeError> {
    let (v, rest) = b.split_at(2);
    let version = u16::from_be_bytes([v[0], v[1]]);
    if version != 1 && version != 2 {
        return Err(DecodeError::HeaderVersion { version });
    }
    let mut t = [0u8; 12];
    let mut d = [0u8; 20];
    let mut n = [[0u8; 8]; 3];
    let (tb, rest) = rest.split_at(12);
    let (db, mut rest) = rest.split_at(20);
    t.copy_from_slice(tb);
    d.copy_from_slice(db);
    for v in &mut n {
        let (x, r) = rest.split_at(8);
        v.copy_from_slice(x);
        rest = r;
    }
    Ok(Header {
        version,
        type_name: TypeName::from_wire(&t).ok_or(DecodeError::HeaderName { field: "type" })?,
        device: DeviceName::from_wire(&d).ok_or(DecodeError::HeaderName { field: "device" })?,
        timestamp: Timestamp(u64::from_be_bytes(n[0])),
        body_size: u64::from_be_bytes(n[1]),
        crc: u64::from_be_bytes(n[2]),
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

/// The parts of a header-version-2 body: content and metadata apart, sizes checked against the
/// body before anything is read.
struct V2Parts<'a> {
    message_id: u32,
    content: &'a [u8],
    content_at: usize,
    meta_header: &'a [u8],
    meta: &'a [u8],
    meta_at: usize,
}

fn split_v2<'a>(h: &'a Header, body: &'a [u8]) -> Result<V2Parts<'a>, DecodeError> {
    let mut r = Reader::new(h, body, 0);
    let ext = usize::from(r.u16("extended header size")?);
    let meta_header_size = usize::from(r.u16("metadata header size")?);
    let meta_size = r.u32("metadata size")? as usize;
    let message_id = r.u32("message id")?;
    if ext < EXT_HEADER_SIZE || ext > body.len() {
        return Err(malformed(
            h,
            0,
            format!(
                "extended header size {ext}: below {EXT_HEADER_SIZE} or past the {}-byte body",
                body.len()
            ),
        ));
    }
    let after_ext = body.len() - ext;
    let tail = meta_header_size
        .checked_add(meta_size)
        .filter(|t| *t <= after_ext)
        .ok_or_else(|| {
            malformed(
                h,
                2,
                format!(
                    "metadata header {meta_header_size} + metadata {meta_size} bytes do not fit the {after_ext} bytes after the extended header"
                ),
            )
        })?;
    let (head, meta_all) = body.split_at(body.len() - tail);
    let (meta_header, meta) = meta_all.split_at(meta_header_size);
    let (_, content) = head.split_at(ext);
    Ok(V2Parts {
        message_id,
        content,
        content_at: ext,
        meta_header,
        meta,
        meta_at: body.len() - tail,
    })
}

fn decode_metadata(h: &Header, p: &V2Parts<'_>) -> Result<Vec<MetaEntry>, DecodeError> {
    if p.meta_header.is_empty() {
        if !p.meta.is_empty() {
            return Err(malformed(h, 4, "metadata without a metadata header"));
        }
        return Ok(Vec::new());
    }
    let mut index = Reader::new(h, p.meta_header, p.meta_at);
    let count = usize::from(index.u16("metadata count")?);
    if p.meta_header.len() != 2 + 8 * count {
        return Err(malformed(
            h,
            p.meta_at,
            format!(
                "metadata header size {} for {count} entries (expected {})",
                p.meta_header.len(),
                2 + 8 * count
            ),
        ));
    }
    let mut values = Reader::new(h, p.meta, p.meta_at + p.meta_header.len());
    // At most 65,535 entries of at least 8 index bytes each, all within the body already read:
    // the capacity is bounded by the body's size.
    let mut metadata = Vec::with_capacity(count);
    for i in 0..count {
        let key_size = usize::from(index.u16("metadata key size")?);
        let encoding = index.u16("metadata encoding")?;
        let value_size = index.u32("metadata value size")? as usize;
        let at = values.at;
        let key = values
            .bytes(key_size, &format!("metadata entry {i}'s key"))
            .map_err(|_| malformed(h, at, format!("metadata entry {i} runs past the body")))?;
        let key = std::str::from_utf8(key)
            .map_err(|_| malformed(h, at, format!("metadata key {i} is not UTF-8")))?
            .to_string();
        let value = values
            .bytes(value_size, &format!("metadata entry {i}'s value"))
            .map_err(|_| malformed(h, at, format!("metadata entry {i} runs past the body")))?
            .to_vec();
        metadata.push(MetaEntry {
            key,
            encoding,
            value,
        });
    }
    if !values.rest.is_empty() {
        return Err(malformed(
            h,
            values.at,
            format!(
                "metadata sizes add up to {} bytes, not {}",
                p.meta.len() - values.rest.len(),
                p.meta.len()
            ),
        ));
    }
    Ok(metadata)
}

/// Decodes a body (CRC already checked) into a message.
pub fn decode_body(h: &Header, body: &[u8]) -> Result<Message, DecodeError> {
    let (message_id, metadata, content, content_at) = if h.version == 2 {
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
        let parts = split_v2(h, body)?;
        let metadata = decode_metadata(h, &parts)?;
        (parts.message_id, metadata, parts.content, parts.content_at)
    } else {
        (0, Vec::new(), body, 0)
    };
    let body = decode_content(h, content, content_at)?;
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

fn decode_content(h: &Header, c: &[u8], base: usize) -> Result<Body, DecodeError> {
    let t = h.type_name.as_str();
    let mut r = Reader::new(h, c, base);
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
            Body::Transform(r.floats("transform")?)
        }
        "POSITION" => position(h, c, base, &mut r)?,
        "TDATA" => tdata(h, c, base, &mut r)?,
        "STATUS" => status(h, &mut r)?,
        "STRING" => {
            let encoding = r.u16("string encoding")?;
            let len = usize::from(r.u16("string length")?);
            if len != r.rest.len() {
                return Err(malformed(
                    h,
                    base + 2,
                    format!("string length {len} but {} bytes follow", r.rest.len()),
                ));
            }
            Body::String {
                encoding,
                text: r.rest.to_vec(),
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
                let resolution_ms = r.u32("resolution")?;
                let at = r.at;
                let coordinate = Name::<32>::from_wire(&r.array::<32>("coordinate name")?)
                    .ok_or_else(|| malformed(h, at, "coordinate name is not ASCII"))?;
                Body::StartTData {
                    resolution_ms,
                    coordinate,
                }
            }
        }
        "RTS_TDATA" => {
            need(1)?;
            let status = r.u8("status")?;
            r.end("status")?;
            Body::RtsTData { status }
        }
        _ if crate::message::query_of(t).is_some() => Body::Query(c.to_vec()),
        _ => Body::Unknown { size: c.len() },
    })
}

/// POSITION: a position and a quaternion in 12, 24 or 28 bytes (a 24-byte one carries x, y, z and
/// w follows from them).
fn position(h: &Header, c: &[u8], base: usize, r: &mut Reader<'_>) -> Result<Body, DecodeError> {
    if !matches!(c.len(), 12 | 24 | 28) {
        return Err(malformed(
            h,
            base,
            format!("{} content bytes, expected 12, 24 or 28", c.len()),
        ));
    }
    let position = r.floats::<3>("position")?;
    let quaternion = match c.len() {
        24 => {
            let [x, y, z] = r.floats::<3>("quaternion")?;
            [x, y, z, (1.0 - x * x - y * y - z * z).max(0.0).sqrt()]
        }
        28 => r.floats::<4>("quaternion")?,
        _ => [0.0, 0.0, 0.0, 1.0],
    };
    Ok(Body::Position {
        position,
        quaternion,
    })
}

/// TDATA: whole tool elements, each named in ASCII.
fn tdata(h: &Header, c: &[u8], base: usize, r: &mut Reader<'_>) -> Result<Body, DecodeError> {
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
    for i in 0..c.len() / TDATA_ELEMENT {
        let at = r.at;
        let name = DeviceName::from_wire(&r.array::<20>("tool name")?)
            .ok_or_else(|| malformed(h, at, format!("tool {i} name is not ASCII")))?;
        let kind = r.u8("tool type")?;
        r.u8("reserved")?;
        tools.push(TDataElement {
            name,
            kind,
            matrix: r.floats("tool matrix")?,
        });
    }
    Ok(Body::TData(tools))
}

/// STATUS: code, subcode, an ASCII error name, and the message up to its first NUL.
fn status(h: &Header, r: &mut Reader<'_>) -> Result<Body, DecodeError> {
    let code = r.u16("status code")?;
    let subcode = r.u64("status subcode")? as i64;
    let at = r.at;
    let error_name = Name::<20>::from_wire(&r.array::<20>("error name")?)
        .ok_or_else(|| malformed(h, at, "error name is not ASCII"))?;
    let text = r.rest;
    let text = text.split(|&b| b == 0).next().unwrap_or(text);
    Ok(Body::Status(Status {
        code,
        subcode,
        error_name,
        message: String::from_utf8_lossy(text).into_owned(),
    }))
}

/// Decodes one message from the front of `buf`. `Ok(None)`: more bytes are needed. `Ok(Some((m,
/// n)))`: a message and the bytes it used. A non-fatal error also consumed its message's bytes;
/// see [`Decoder`] for a stream.
pub fn decode(buf: &[u8], max_body: u64) -> Result<Option<(Message, usize)>, (DecodeError, usize)> {
    let Some((hb, rest)) = buf.split_first_chunk::<HEADER_SIZE>() else {
        return Ok(None);
    };
    let h = decode_header(hb).map_err(|e| (e, 0))?;
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
    // Below the limit, so it fits a usize.
    let body_size = usize::try_from(h.body_size).unwrap_or(usize::MAX);
    let Some(body) = rest.get(..body_size) else {
        return Ok(None);
    };
    let total = HEADER_SIZE + body_size;
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
        match decode(
            self.buf.get(self.start..).unwrap_or_default(),
            self.max_body,
        ) {
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
