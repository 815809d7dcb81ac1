//! The RTDE wire format (TCP 30004): framing, every package type in both directions and both
//! protocol versions, and recipes (packing and unpacking data packages). No I/O.
//!
//! A frame is `u16 size` (including the 3-byte header), `u8 type`, then the payload; all numbers
//! big-endian. Version differences (protocol 1 vs 2): the output setup request carries a
//! frequency and its reply a recipe id only in v2; output data packages carry their recipe id only
//! in v2; text messages from the controller are `level, message` in v1 and
//! `len, message, len, source, level` in v2.

use crate::error::RtdeError;
use crate::types::{DataType, Value, input_type, output_type};

/// Package type codes.
pub mod kind {
    /// `V`: request protocol version.
    pub const REQUEST_PROTOCOL_VERSION: u8 = b'V';
    /// `v`: controller (URControl) version.
    pub const GET_URCONTROL_VERSION: u8 = b'v';
    /// `M`: text message.
    pub const TEXT_MESSAGE: u8 = b'M';
    /// `U`: data package.
    pub const DATA_PACKAGE: u8 = b'U';
    /// `O`: set up outputs.
    pub const SETUP_OUTPUTS: u8 = b'O';
    /// `I`: set up inputs.
    pub const SETUP_INPUTS: u8 = b'I';
    /// `S`: start.
    pub const START: u8 = b'S';
    /// `P`: pause.
    pub const PAUSE: u8 = b'P';
}

/// The header size, bytes (included in a frame's declared size).
pub const HEADER_SIZE: usize = 3;
/// The largest frame (the size field is 16 bits).
pub const MAX_FRAME: usize = u16::MAX as usize;
/// The newest protocol version.
pub const PROTOCOL_V2: u16 = 2;

/// The controller software version (`major.minor.bugfix.build`, e.g. 5.11.1.108318).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct ControllerVersion {
    /// Major (3 = CB3, 5 = e-Series, 10 = PolyScope X).
    pub major: u32,
    /// Minor.
    pub minor: u32,
    /// Bug-fix.
    pub bugfix: u32,
    /// Build.
    pub build: u32,
}

impl ControllerVersion {
    /// The controller's RTDE output rate: 125 Hz before major 5 (CB3), 500 Hz after.
    pub fn max_frequency(&self) -> f64 {
        if self.major < 5 { 125.0 } else { 500.0 }
    }
}

impl std::fmt::Display for ControllerVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}.{}.{}.{}",
            self.major, self.minor, self.bugfix, self.build
        )
    }
}

/// A text message (level 0 exception, 1 error, 2 warning, 3 info).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TextMessage {
    /// Severity, 0 (exception) … 3 (info).
    pub level: u8,
    /// The text.
    pub message: String,
    /// Who sent it (v2 only; empty in v1).
    pub source: String,
}

/// A package from the client to the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum Request<'a> {
    /// `V`: the protocol version the client wants.
    ProtocolVersion(u16),
    /// `v`.
    ControllerVersion,
    /// `M` (v2 layout).
    Text(TextMessage),
    /// `U`: input values, packed for the input recipe `recipe_id`.
    Data {
        /// Input recipe id.
        recipe_id: u8,
        /// The packed values.
        payload: &'a [u8],
    },
    /// `O`: output variable names, with the frequency in v2.
    SetupOutputs {
        /// Requested output frequency, Hz (v2 only).
        frequency: Option<f64>,
        /// Variable names.
        names: Vec<String>,
    },
    /// `I`: input variable names.
    SetupInputs {
        /// Variable names.
        names: Vec<String>,
    },
    /// `S`.
    Start,
    /// `P`.
    Pause,
}

/// A package from the controller to the client.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply<'a> {
    /// `V`: accepted or not.
    ProtocolVersion(bool),
    /// `v`.
    ControllerVersion(ControllerVersion),
    /// `M`.
    Text(TextMessage),
    /// `U`: output values packed for the output recipe (id present in v2).
    Data {
        /// Output recipe id (v2).
        recipe_id: Option<u8>,
        /// The packed values.
        payload: &'a [u8],
    },
    /// `O`: the types of the requested outputs (or `NOT_FOUND`), id in v2.
    SetupOutputs {
        /// Output recipe id (v2).
        recipe_id: Option<u8>,
        /// One type name (or `NOT_FOUND` / `IN_USE`) per variable.
        types: Vec<String>,
    },
    /// `I`: the input recipe id and types (or `NOT_FOUND` / `IN_USE`).
    SetupInputs {
        /// Input recipe id (0 when refused).
        recipe_id: u8,
        /// One type name (or `NOT_FOUND` / `IN_USE`) per variable.
        types: Vec<String>,
    },
    /// `S`: accepted or not.
    Start(bool),
    /// `P`: accepted or not.
    Pause(bool),
}

fn begin(out: &mut Vec<u8>, kind: u8) -> usize {
    let at = out.len();
    out.extend_from_slice(&[0, 0, kind]);
    at
}

fn finish(out: &mut Vec<u8>, at: usize) -> Result<(), RtdeError> {
    let size = out.len() - at;
    if size > MAX_FRAME {
        out.truncate(at);
        return Err(RtdeError::TooLarge(size));
    }
    let s = (size as u16).to_be_bytes();
    out[at] = s[0];
    out[at + 1] = s[1];
    Ok(())
}

fn short_str(out: &mut Vec<u8>, s: &str, field: &'static str) -> Result<(), RtdeError> {
    let b = s.as_bytes();
    let n = u8::try_from(b.len()).map_err(|_| RtdeError::FieldTooLong {
        field,
        len: b.len(),
    })?;
    out.push(n);
    out.extend_from_slice(b);
    Ok(())
}

/// The v2 text layout (`len, message, len, source, level`); on error the frame begun at `at` is
/// removed.
fn encode_text_v2(t: &TextMessage, at: usize, out: &mut Vec<u8>) -> Result<(), RtdeError> {
    let r =
        short_str(out, &t.message, "message").and_then(|()| short_str(out, &t.source, "source"));
    if let Err(e) = r {
        out.truncate(at);
        return Err(e);
    }
    out.push(t.level);
    Ok(())
}

fn names_csv(out: &mut Vec<u8>, names: &[String]) {
    for (i, n) in names.iter().enumerate() {
        if i > 0 {
            out.push(b',');
        }
        out.extend_from_slice(n.as_bytes());
    }
}

/// Appends a client package to `out` in protocol `version`'s layout.
pub fn encode_request(req: &Request<'_>, version: u16, out: &mut Vec<u8>) -> Result<(), RtdeError> {
    let at;
    match req {
        Request::ProtocolVersion(v) => {
            at = begin(out, kind::REQUEST_PROTOCOL_VERSION);
            out.extend_from_slice(&v.to_be_bytes());
        }
        Request::ControllerVersion => at = begin(out, kind::GET_URCONTROL_VERSION),
        Request::Text(t) => {
            at = begin(out, kind::TEXT_MESSAGE);
            encode_text_v2(t, at, out)?;
        }
        Request::Data { recipe_id, payload } => {
            at = begin(out, kind::DATA_PACKAGE);
            out.push(*recipe_id);
            out.extend_from_slice(payload);
        }
        Request::SetupOutputs { frequency, names } => {
            at = begin(out, kind::SETUP_OUTPUTS);
            if version >= PROTOCOL_V2 {
                out.extend_from_slice(&frequency.unwrap_or(125.0).to_be_bytes());
            }
            names_csv(out, names);
        }
        Request::SetupInputs { names } => {
            at = begin(out, kind::SETUP_INPUTS);
            names_csv(out, names);
        }
        Request::Start => at = begin(out, kind::START),
        Request::Pause => at = begin(out, kind::PAUSE),
    }
    finish(out, at)
}

/// Appends a controller package to `out` in protocol `version`'s layout.
pub fn encode_reply(rep: &Reply<'_>, version: u16, out: &mut Vec<u8>) -> Result<(), RtdeError> {
    let at;
    match rep {
        Reply::ProtocolVersion(ok) => {
            at = begin(out, kind::REQUEST_PROTOCOL_VERSION);
            out.push(u8::from(*ok));
        }
        Reply::ControllerVersion(v) => {
            at = begin(out, kind::GET_URCONTROL_VERSION);
            for x in [v.major, v.minor, v.bugfix, v.build] {
                out.extend_from_slice(&x.to_be_bytes());
            }
        }
        Reply::Text(t) => {
            at = begin(out, kind::TEXT_MESSAGE);
            if version >= PROTOCOL_V2 {
                encode_text_v2(t, at, out)?;
            } else {
                out.push(t.level);
                out.extend_from_slice(t.message.as_bytes());
            }
        }
        Reply::Data { recipe_id, payload } => {
            at = begin(out, kind::DATA_PACKAGE);
            if version >= PROTOCOL_V2 {
                out.push(recipe_id.unwrap_or(1));
            }
            out.extend_from_slice(payload);
        }
        Reply::SetupOutputs { recipe_id, types } => {
            at = begin(out, kind::SETUP_OUTPUTS);
            if version >= PROTOCOL_V2 {
                out.push(recipe_id.unwrap_or(1));
            }
            names_csv(out, types);
        }
        Reply::SetupInputs { recipe_id, types } => {
            at = begin(out, kind::SETUP_INPUTS);
            out.push(*recipe_id);
            names_csv(out, types);
        }
        Reply::Start(ok) => {
            at = begin(out, kind::START);
            out.push(u8::from(*ok));
        }
        Reply::Pause(ok) => {
            at = begin(out, kind::PAUSE);
            out.push(u8::from(*ok));
        }
    }
    finish(out, at)
}

fn malformed(kind: u8, what: impl Into<String>) -> RtdeError {
    RtdeError::Malformed {
        kind: char::from(kind),
        what: what.into(),
    }
}

fn exact<const N: usize>(kind: u8, p: &[u8]) -> Result<[u8; N], RtdeError> {
    <[u8; N]>::try_from(p)
        .map_err(|_| malformed(kind, format!("payload of {} bytes, expected {N}", p.len())))
}

fn text(kind: u8, b: &[u8], field: &str) -> Result<String, RtdeError> {
    std::str::from_utf8(b).map(str::to_string).map_err(|e| {
        malformed(
            kind,
            format!("{field} is not UTF-8 (byte {})", e.valid_up_to()),
        )
    })
}

/// Splits a comma-separated list; one trailing comma (ur_rtde sends one) is dropped. Names are
/// taken exactly (no trimming); an empty name is malformed.
fn csv_list(kind: u8, b: &[u8]) -> Result<Vec<String>, RtdeError> {
    let s = text(kind, b, "name list")?;
    let s = s.strip_suffix(',').unwrap_or(&s);
    if s.is_empty() {
        return Ok(Vec::new());
    }
    s.split(',')
        .enumerate()
        .map(|(i, n)| {
            if n.is_empty() {
                Err(malformed(kind, format!("empty name at position {}", i + 1)))
            } else {
                Ok(n.to_string())
            }
        })
        .collect()
}

fn text_v2(kind: u8, p: &[u8]) -> Result<TextMessage, RtdeError> {
    let err = || malformed(kind, "text message shorter than its length fields");
    let (&n, rest) = p.split_first().ok_or_else(err)?;
    let msg = rest.get(..usize::from(n)).ok_or_else(err)?;
    let rest = &rest[usize::from(n)..];
    let (&m, rest) = rest.split_first().ok_or_else(err)?;
    let src = rest.get(..usize::from(m)).ok_or_else(err)?;
    let rest = &rest[usize::from(m)..];
    let [level] = exact::<1>(kind, rest)?;
    Ok(TextMessage {
        level,
        message: text(kind, msg, "message")?,
        source: text(kind, src, "source")?,
    })
}

fn flag(kind: u8, p: &[u8]) -> Result<bool, RtdeError> {
    Ok(exact::<1>(kind, p)?[0] != 0)
}

/// Decodes a client package's payload (`kind` from its header) under protocol `version`.
pub fn decode_request(kind: u8, p: &[u8], version: u16) -> Result<Request<'_>, RtdeError> {
    Ok(match kind {
        kind::REQUEST_PROTOCOL_VERSION => {
            Request::ProtocolVersion(u16::from_be_bytes(exact::<2>(kind, p)?))
        }
        kind::GET_URCONTROL_VERSION => {
            exact::<0>(kind, p)?;
            Request::ControllerVersion
        }
        kind::TEXT_MESSAGE => Request::Text(text_v2(kind, p)?),
        kind::DATA_PACKAGE => {
            let (&recipe_id, payload) = p
                .split_first()
                .ok_or_else(|| malformed(kind, "no recipe id"))?;
            Request::Data { recipe_id, payload }
        }
        kind::SETUP_OUTPUTS => {
            if version >= PROTOCOL_V2 {
                let f = p
                    .get(..8)
                    .ok_or_else(|| malformed(kind, "shorter than the 8-byte frequency"))?;
                let frequency = f64::from_be_bytes(exact::<8>(kind, f)?);
                Request::SetupOutputs {
                    frequency: Some(frequency),
                    names: csv_list(kind, &p[8..])?,
                }
            } else {
                Request::SetupOutputs {
                    frequency: None,
                    names: csv_list(kind, p)?,
                }
            }
        }
        kind::SETUP_INPUTS => Request::SetupInputs {
            names: csv_list(kind, p)?,
        },
        kind::START => {
            exact::<0>(kind, p)?;
            Request::Start
        }
        kind::PAUSE => {
            exact::<0>(kind, p)?;
            Request::Pause
        }
        other => return Err(RtdeError::UnknownType(other)),
    })
}

/// Decodes a controller package's payload (`kind` from its header) under protocol `version`.
pub fn decode_reply(kind: u8, p: &[u8], version: u16) -> Result<Reply<'_>, RtdeError> {
    Ok(match kind {
        kind::REQUEST_PROTOCOL_VERSION => Reply::ProtocolVersion(flag(kind, p)?),
        kind::GET_URCONTROL_VERSION => {
            let b = exact::<16>(kind, p)?;
            let w = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
            Reply::ControllerVersion(ControllerVersion {
                major: w(0),
                minor: w(4),
                bugfix: w(8),
                build: w(12),
            })
        }
        kind::TEXT_MESSAGE => {
            if version >= PROTOCOL_V2 {
                Reply::Text(text_v2(kind, p)?)
            } else {
                let (&level, msg) = p
                    .split_first()
                    .ok_or_else(|| malformed(kind, "no level byte"))?;
                Reply::Text(TextMessage {
                    level,
                    message: text(kind, msg, "message")?,
                    source: String::new(),
                })
            }
        }
        kind::DATA_PACKAGE => {
            if version >= PROTOCOL_V2 {
                let (&id, payload) = p
                    .split_first()
                    .ok_or_else(|| malformed(kind, "no recipe id"))?;
                Reply::Data {
                    recipe_id: Some(id),
                    payload,
                }
            } else {
                Reply::Data {
                    recipe_id: None,
                    payload: p,
                }
            }
        }
        kind::SETUP_OUTPUTS => {
            if version >= PROTOCOL_V2 {
                let (&id, rest) = p
                    .split_first()
                    .ok_or_else(|| malformed(kind, "no recipe id"))?;
                Reply::SetupOutputs {
                    recipe_id: Some(id),
                    types: csv_list(kind, rest)?,
                }
            } else {
                Reply::SetupOutputs {
                    recipe_id: None,
                    types: csv_list(kind, p)?,
                }
            }
        }
        kind::SETUP_INPUTS => {
            let (&id, rest) = p
                .split_first()
                .ok_or_else(|| malformed(kind, "no recipe id"))?;
            Reply::SetupInputs {
                recipe_id: id,
                types: csv_list(kind, rest)?,
            }
        }
        kind::START => Reply::Start(flag(kind, p)?),
        kind::PAUSE => Reply::Pause(flag(kind, p)?),
        other => return Err(RtdeError::UnknownType(other)),
    })
}

/// One frame cut from the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    /// Package type.
    pub kind: u8,
    /// Payload (after the header).
    pub payload: &'a [u8],
    /// Byte offset of the frame in the stream (for error messages).
    pub offset: u64,
}

/// Cuts frames out of a byte stream that arrives in arbitrary pieces. Memory is bounded by one
/// frame (64 KiB) plus the last piece pushed.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    start: usize,
    consumed: u64,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 && (self.start == self.buf.len() || self.start > 1 << 16) {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes held that do not yet form a complete frame.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// The next complete frame, `None` when more bytes are needed, or an error for a size below
    /// the header (the stream is out of step and cannot be resynchronised: close it).
    pub fn next_frame(&mut self) -> Result<Option<Frame<'_>>, RtdeError> {
        let avail = &self.buf[self.start..];
        if avail.len() < HEADER_SIZE {
            return Ok(None);
        }
        let size = usize::from(u16::from_be_bytes([avail[0], avail[1]]));
        let offset = self.consumed;
        if size < HEADER_SIZE {
            return Err(RtdeError::BadFrameSize { offset, size });
        }
        if avail.len() < size {
            return Ok(None);
        }
        let begin = self.start;
        self.start += size;
        self.consumed += size as u64;
        Ok(Some(Frame {
            kind: self.buf[begin + 2],
            payload: &self.buf[begin + HEADER_SIZE..begin + size],
            offset,
        }))
    }
}

/// Which side of the controller a recipe describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Controller → client.
    Output,
    /// Client → controller.
    Input,
}

/// A recipe: the variables of one data package, in order, with their types.
#[derive(Debug, Clone, PartialEq)]
pub struct Recipe {
    /// Recipe id (outputs: 1 on protocol v1, where packages carry no id).
    pub id: u8,
    /// Variable names.
    pub names: Vec<String>,
    /// Their types.
    pub types: Vec<DataType>,
    size: usize,
}

impl Recipe {
    /// A recipe from names, typed from the controller's variable table; an unknown name is
    /// `NotFound`.
    pub fn from_table(id: u8, names: &[&str], direction: Direction) -> Result<Recipe, RtdeError> {
        let types = names
            .iter()
            .map(|n| {
                match direction {
                    Direction::Output => output_type(n),
                    Direction::Input => input_type(n),
                }
                .ok_or_else(|| RtdeError::NotFound {
                    names: (*n).to_string(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Recipe::new(
            id,
            names.iter().map(|n| (*n).to_string()).collect(),
            types,
        ))
    }

    /// A recipe from names and types.
    pub fn new(id: u8, names: Vec<String>, types: Vec<DataType>) -> Recipe {
        let size = types.iter().map(|t| t.size()).sum();
        Recipe {
            id,
            names,
            types,
            size,
        }
    }

    /// A recipe from the controller's setup reply: every `NOT_FOUND` and `IN_USE` is named.
    pub fn from_reply(id: u8, names: &[String], types: &[String]) -> Result<Recipe, RtdeError> {
        if names.len() != types.len() {
            return Err(RtdeError::RecipeMismatch {
                requested: names.len(),
                answered: types.len(),
            });
        }
        let pick = |word: &str| {
            names
                .iter()
                .zip(types)
                .filter(|(_, t)| t.as_str() == word)
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let not_found = pick("NOT_FOUND");
        if !not_found.is_empty() {
            return Err(RtdeError::NotFound { names: not_found });
        }
        let in_use = pick("IN_USE");
        if !in_use.is_empty() {
            return Err(RtdeError::InUse { names: in_use });
        }
        let parsed = names
            .iter()
            .zip(types)
            .map(|(n, t)| {
                DataType::from_name(t).ok_or_else(|| RtdeError::UnknownDataType {
                    name: n.clone(),
                    type_name: t.clone(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Recipe::new(id, names.to_vec(), parsed))
    }

    /// Packed size of one data package's values, bytes.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The position of `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Decodes a data package's values into `out` (cleared first; no allocation once `out` has
    /// the capacity).
    pub fn unpack(&self, payload: &[u8], out: &mut Vec<Value>) -> Result<(), RtdeError> {
        if payload.len() != self.size {
            return Err(RtdeError::DataSize {
                id: self.id,
                got: payload.len(),
                expected: self.size,
            });
        }
        out.clear();
        let mut at = 0;
        for t in &self.types {
            out.push(Value::decode(*t, &payload[at..at + t.size()]));
            at += t.size();
        }
        Ok(())
    }

    /// Packs `values` (one per variable, of the recipe's types) onto `out`.
    pub fn pack(&self, values: &[Value], out: &mut Vec<u8>) -> Result<(), RtdeError> {
        if values.len() != self.types.len() {
            return Err(RtdeError::RecipeMismatch {
                requested: self.types.len(),
                answered: values.len(),
            });
        }
        for ((v, t), n) in values.iter().zip(&self.types).zip(&self.names) {
            if v.data_type() != *t {
                return Err(RtdeError::TypeMismatch {
                    name: n.clone(),
                    expected: *t,
                    got: v.data_type(),
                });
            }
        }
        for v in values {
            v.encode(out);
        }
        Ok(())
    }

    /// Appends a whole input data package (`U`, recipe id, values) to `out`.
    pub fn encode_input_package(
        &self,
        values: &[Value],
        out: &mut Vec<u8>,
    ) -> Result<(), RtdeError> {
        let at = begin(out, kind::DATA_PACKAGE);
        out.push(self.id);
        if let Err(e) = self.pack(values, out) {
            out.truncate(at);
            return Err(e);
        }
        finish(out, at)
    }

    /// Appends a whole output data package (`U`, recipe id in v2, values) to `out`.
    pub fn encode_output_package(
        &self,
        values: &[Value],
        version: u16,
        out: &mut Vec<u8>,
    ) -> Result<(), RtdeError> {
        let at = begin(out, kind::DATA_PACKAGE);
        if version >= PROTOCOL_V2 {
            out.push(self.id);
        }
        if let Err(e) = self.pack(values, out) {
            out.truncate(at);
            return Err(e);
        }
        finish(out, at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(bytes: &[u8]) -> Vec<(u8, Vec<u8>)> {
        let mut d = FrameDecoder::new();
        d.push(bytes);
        let mut v = Vec::new();
        while let Some(f) = d.next_frame().unwrap() {
            v.push((f.kind, f.payload.to_vec()));
        }
        v
    }

    #[test]
    fn golden_handshake_bytes() {
        let mut b = Vec::new();
        encode_request(&Request::ProtocolVersion(2), 2, &mut b).unwrap();
        assert_eq!(b, [0x00, 0x05, 0x56, 0x00, 0x02]);
        b.clear();
        encode_request(&Request::Start, 2, &mut b).unwrap();
        assert_eq!(b, [0x00, 0x03, 0x53], "a bare START has size 3");
        b.clear();
        encode_request(
            &Request::SetupOutputs {
                frequency: Some(125.0),
                names: vec!["timestamp".into(), "actual_q".into()],
            },
            2,
            &mut b,
        )
        .unwrap();
        let mut expect = vec![0x00, 29, b'O', 0x40, 0x5f, 0x40, 0, 0, 0, 0, 0];
        expect.extend_from_slice(b"timestamp,actual_q");
        assert_eq!(b, expect);
        b.clear();
        encode_reply(
            &Reply::ControllerVersion(ControllerVersion {
                major: 5,
                minor: 11,
                bugfix: 1,
                build: 108318,
            }),
            2,
            &mut b,
        )
        .unwrap();
        assert_eq!(
            b,
            [
                0, 19, b'v', 0, 0, 0, 5, 0, 0, 0, 11, 0, 0, 0, 1, 0, 1, 0xa7, 0x1e
            ]
        );
    }

    #[test]
    fn trailing_comma_is_accepted() {
        let r = decode_request(kind::SETUP_INPUTS, b"input_int_register_0,", 2).unwrap();
        assert_eq!(
            r,
            Request::SetupInputs {
                names: vec!["input_int_register_0".into()]
            }
        );
    }

    #[test]
    fn every_package_round_trips_in_both_versions() {
        for version in [1u16, 2] {
            let reqs = [
                Request::ProtocolVersion(2),
                Request::ControllerVersion,
                Request::Text(TextMessage {
                    level: 2,
                    message: "hello".into(),
                    source: "mocomp".into(),
                }),
                Request::Data {
                    recipe_id: 3,
                    payload: &[1, 2, 3],
                },
                Request::SetupOutputs {
                    frequency: (version >= 2).then_some(500.0),
                    names: vec!["timestamp".into(), "actual_q".into()],
                },
                Request::SetupInputs {
                    names: vec!["input_int_register_24".into()],
                },
                Request::Start,
                Request::Pause,
            ];
            for r in &reqs {
                let mut b = Vec::new();
                encode_request(r, version, &mut b).unwrap();
                let f = frames(&b);
                assert_eq!(f.len(), 1);
                assert_eq!(&decode_request(f[0].0, &f[0].1, version).unwrap(), r);
            }
            let reps = [
                Reply::ProtocolVersion(true),
                Reply::ControllerVersion(ControllerVersion {
                    major: 3,
                    minor: 15,
                    bugfix: 7,
                    build: 106331,
                }),
                Reply::Text(TextMessage {
                    level: 3,
                    message: "info".into(),
                    source: if version >= 2 {
                        "ctrl".into()
                    } else {
                        String::new()
                    },
                }),
                Reply::Data {
                    recipe_id: (version >= 2).then_some(1),
                    payload: &[9, 8],
                },
                Reply::SetupOutputs {
                    recipe_id: (version >= 2).then_some(1),
                    types: vec!["DOUBLE".into(), "VECTOR6D".into()],
                },
                Reply::SetupInputs {
                    recipe_id: 2,
                    types: vec!["INT32".into(), "IN_USE".into()],
                },
                Reply::Start(true),
                Reply::Pause(false),
            ];
            for r in &reps {
                let mut b = Vec::new();
                encode_reply(r, version, &mut b).unwrap();
                let f = frames(&b);
                assert_eq!(&decode_reply(f[0].0, &f[0].1, version).unwrap(), r);
            }
        }
    }

    #[test]
    fn decoder_reassembles_any_split_and_reports_bad_sizes() {
        let mut stream = Vec::new();
        for i in 0..50u16 {
            encode_request(&Request::ProtocolVersion(i), 2, &mut stream).unwrap();
            encode_request(&Request::Start, 2, &mut stream).unwrap();
        }
        for chunk in [1, 2, 3, 7, 64] {
            let mut d = FrameDecoder::new();
            let mut n = 0;
            for piece in stream.chunks(chunk) {
                d.push(piece);
                while let Some(f) = d.next_frame().unwrap() {
                    n += 1;
                    assert!(f.kind == b'V' || f.kind == b'S');
                }
            }
            assert_eq!(n, 100);
            assert_eq!(d.pending(), 0);
        }
        let mut d = FrameDecoder::new();
        d.push(&[0, 3, b'S', 0, 2, b'S']);
        assert!(d.next_frame().unwrap().is_some());
        let e = d.next_frame().unwrap_err();
        assert_eq!(
            e.to_string(),
            "RTDE frame at byte 3 declares size 2, below the 3-byte header"
        );
    }

    #[test]
    fn recipes_name_missing_and_busy_variables() {
        let names: Vec<String> = ["actual_q", "no_such", "speed_scaling", "other"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let types: Vec<String> = ["VECTOR6D", "NOT_FOUND", "DOUBLE", "NOT_FOUND"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let e = Recipe::from_reply(1, &names, &types).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the controller does not know RTDE variable(s) no_such, other (NOT_FOUND)"
        );
        let types: Vec<String> = ["VECTOR6D", "IN_USE", "DOUBLE", "INT32"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let e = Recipe::from_reply(1, &names, &types).unwrap_err();
        assert!(e.to_string().contains("no_such"), "{e}");
        assert!(e.to_string().contains("IN_USE"), "{e}");
        let e = Recipe::from_table(1, &["actual_q", "bogus"], Direction::Output).unwrap_err();
        assert!(e.to_string().contains("bogus"));
    }

    #[test]
    fn recipe_pack_unpack_and_errors() {
        let r = Recipe::from_table(
            2,
            &["input_int_register_24", "input_double_register_24"],
            Direction::Input,
        )
        .unwrap();
        assert_eq!(r.size(), 12);
        let vals = [Value::Int32(7), Value::Double(0.25)];
        let mut b = Vec::new();
        r.encode_input_package(&vals, &mut b).unwrap();
        assert_eq!(b.len(), 3 + 1 + 12);
        let f = frames(&b);
        let Request::Data { recipe_id, payload } = decode_request(f[0].0, &f[0].1, 2).unwrap()
        else {
            panic!("not data")
        };
        assert_eq!(recipe_id, 2);
        let mut out = Vec::new();
        r.unpack(payload, &mut out).unwrap();
        assert_eq!(out, vals);
        let e = r.unpack(&payload[..5], &mut out).unwrap_err();
        assert_eq!(
            e.to_string(),
            "data package for recipe 2 has 5 bytes, the recipe needs 12"
        );
        let e = r
            .pack(&[Value::Double(1.0), Value::Double(0.25)], &mut b)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "RTDE variable input_int_register_24 is INT32, the value given is DOUBLE"
        );
    }
}
