//! A blocking RTDE client connection: handshake (protocol 2, falling back to 1), controller
//! version, output and input recipes, start/pause, sending inputs and receiving data packages.
//! Text messages that arrive between replies are kept (see [`RtdeConnection::texts`]), never
//! mistaken for replies.

use crate::codec::{
    ControllerVersion, FrameDecoder, PROTOCOL_V2, Recipe, Reply, Request, TextMessage,
    decode_reply, encode_request, kind,
};
use crate::error::{RtdeError, UrError};
use crate::types::Value;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

/// The standard RTDE port.
pub const RTDE_PORT: u16 = 30004;

/// Most text messages kept (older ones are dropped and counted).
const MAX_TEXTS: usize = 64;

/// An open RTDE connection.
#[derive(Debug)]
pub struct RtdeConnection {
    stream: TcpStream,
    addr: SocketAddr,
    decoder: FrameDecoder,
    version: u16,
    out: Vec<u8>,
    read_buf: Box<[u8; 8192]>,
    texts: Vec<TextMessage>,
    texts_dropped: u64,
    reply_timeout: Duration,
}

impl RtdeConnection {
    /// Connects (TCP_NODELAY) within `timeout`; replies are awaited for up to `timeout` too.
    pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<RtdeConnection, UrError> {
        let stream = TcpStream::connect_timeout(&addr, timeout)
            .map_err(|e| UrError::io(format!("connecting to RTDE at {addr}"), e))?;
        stream
            .set_nodelay(true)
            .map_err(|e| UrError::io("setting TCP_NODELAY", e))?;
        Ok(RtdeConnection {
            stream,
            addr,
            decoder: FrameDecoder::new(),
            version: 1,
            out: Vec::with_capacity(512),
            read_buf: Box::new([0; 8192]),
            texts: Vec::new(),
            texts_dropped: 0,
            reply_timeout: timeout,
        })
    }

    /// The protocol version in use (1 until [`Self::negotiate`] succeeds with 2).
    pub fn version(&self) -> u16 {
        self.version
    }

    /// The controller's address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Text messages received so far (oldest first; at most 64 kept).
    pub fn texts(&self) -> &[TextMessage] {
        &self.texts
    }

    /// Requests protocol 2, then 1; returns the version agreed.
    pub fn negotiate(&mut self) -> Result<u16, UrError> {
        for v in [PROTOCOL_V2, 1] {
            self.send(&Request::ProtocolVersion(v))?;
            let ok = self.reply(kind::REQUEST_PROTOCOL_VERSION, |r| match r {
                Reply::ProtocolVersion(ok) => Some(ok),
                _ => None,
            })?;
            if ok {
                self.version = v;
                return Ok(v);
            }
        }
        Err(UrError::NoProtocol)
    }

    /// The controller's software version.
    pub fn controller_version(&mut self) -> Result<ControllerVersion, UrError> {
        self.send(&Request::ControllerVersion)?;
        self.reply(kind::GET_URCONTROL_VERSION, |r| match r {
            Reply::ControllerVersion(v) => Some(v),
            _ => None,
        })
    }

    /// Sets up the output recipe (`frequency` is sent in protocol 2 only); `NOT_FOUND` names the
    /// variables.
    pub fn setup_outputs(&mut self, frequency: f64, names: &[&str]) -> Result<Recipe, UrError> {
        let names: Vec<String> = names.iter().map(|s| (*s).to_string()).collect();
        self.send(&Request::SetupOutputs {
            frequency: Some(frequency),
            names: names.clone(),
        })?;
        let (id, types) = self.reply(kind::SETUP_OUTPUTS, |r| match r {
            Reply::SetupOutputs { recipe_id, types } => Some((recipe_id.unwrap_or(1), types)),
            _ => None,
        })?;
        Recipe::from_reply(id, &names, &types).map_err(|e| self.rtde_err("output recipe", e))
    }

    /// Sets up an input recipe; `NOT_FOUND` and `IN_USE` name the variables.
    pub fn setup_inputs(&mut self, names: &[&str]) -> Result<Recipe, UrError> {
        let names: Vec<String> = names.iter().map(|s| (*s).to_string()).collect();
        self.send(&Request::SetupInputs {
            names: names.clone(),
        })?;
        let (id, types) = self.reply(kind::SETUP_INPUTS, |r| match r {
            Reply::SetupInputs { recipe_id, types } => Some((recipe_id, types)),
            _ => None,
        })?;
        Recipe::from_reply(id, &names, &types).map_err(|e| self.rtde_err("input recipe", e))
    }

    /// Starts synchronisation (data packages flow after this).
    pub fn start(&mut self) -> Result<(), UrError> {
        self.accepted(
            &Request::Start,
            kind::START,
            "RTDE start (is there an output recipe?)",
        )
    }

    /// Pauses synchronisation. Data packages already on the way are skipped.
    pub fn pause(&mut self) -> Result<(), UrError> {
        self.accepted(&Request::Pause, kind::PAUSE, "RTDE pause")
    }

    /// Sends a request whose reply is one accepted/refused byte.
    fn accepted(&mut self, req: &Request<'_>, want: u8, what: &str) -> Result<(), UrError> {
        self.send(req)?;
        let ok = self.reply(want, |r| match r {
            Reply::Start(ok) | Reply::Pause(ok) => Some(ok),
            _ => None,
        })?;
        if ok {
            Ok(())
        } else {
            Err(UrError::Refused { what: what.into() })
        }
    }

    /// Sends a text message to the controller's log (protocol 2).
    pub fn send_text(&mut self, message: &str, source: &str, level: u8) -> Result<(), UrError> {
        self.send(&Request::Text(TextMessage {
            level,
            message: message.to_string(),
            source: source.to_string(),
        }))
    }

    /// Sends one input data package.
    pub fn send_inputs(&mut self, recipe: &Recipe, values: &[Value]) -> Result<(), UrError> {
        self.out.clear();
        recipe
            .encode_input_package(values, &mut self.out)
            .map_err(|e| UrError::Rtde {
                context: format!("encoding inputs for recipe {}", recipe.id),
                cause: e,
            })?;
        self.stream
            .write_all(&self.out)
            .map_err(|e| UrError::io(format!("sending RTDE inputs to {}", self.addr), e))
    }

    /// Blocks (up to the reply timeout) for the next data package of `recipe` and unpacks it
    /// into `values`. Older packages already buffered are skipped when `newest` is set.
    pub fn receive(
        &mut self,
        recipe: &Recipe,
        values: &mut Vec<Value>,
        newest: bool,
    ) -> Result<(), UrError> {
        let deadline = Instant::now() + self.reply_timeout;
        let mut got = false;
        loop {
            while let Some(f) = self.decoder.next_frame().map_err(|e| UrError::Rtde {
                context: format!("RTDE stream from {}", self.addr),
                cause: e,
            })? {
                match decode_reply(f.kind, f.payload, self.version) {
                    Ok(Reply::Data { payload, .. }) => {
                        recipe.unpack(payload, values).map_err(|e| UrError::Rtde {
                            context: format!("data package from {}", self.addr),
                            cause: e,
                        })?;
                        got = true;
                        if !newest {
                            return Ok(());
                        }
                    }
                    Ok(Reply::Text(t)) => keep_text(&mut self.texts, &mut self.texts_dropped, t),
                    Ok(_) | Err(RtdeError::UnknownType(_)) => {}
                    Err(e) => {
                        return Err(UrError::Rtde {
                            context: format!("RTDE stream from {}", self.addr),
                            cause: e,
                        });
                    }
                }
            }
            if got {
                return Ok(());
            }
            self.fill(deadline, "an RTDE data package")?;
        }
    }

    /// Splits off a handle for writing from another thread (same socket).
    pub fn try_clone_stream(&self) -> Result<TcpStream, UrError> {
        self.stream
            .try_clone()
            .map_err(|e| UrError::io("cloning the RTDE socket", e))
    }

    /// Closes the socket (both directions).
    pub fn shutdown(&self) {
        self.stream.shutdown(std::net::Shutdown::Both).ok();
    }

    fn rtde_err(&self, what: &str, e: RtdeError) -> UrError {
        UrError::Rtde {
            context: format!("{what} on {}", self.addr),
            cause: e,
        }
    }

    fn send(&mut self, r: &Request<'_>) -> Result<(), UrError> {
        self.out.clear();
        encode_request(r, self.version, &mut self.out).map_err(|e| self.rtde_err("encoding", e))?;
        self.stream
            .write_all(&self.out)
            .map_err(|e| UrError::io(format!("sending to RTDE at {}", self.addr), e))
    }

    /// Reads until a package of `want` arrives (others, data and text, are skipped or kept).
    fn reply<T>(&mut self, want: u8, pick: impl Fn(Reply<'_>) -> Option<T>) -> Result<T, UrError> {
        let deadline = Instant::now() + self.reply_timeout;
        loop {
            while let Some(f) = self.decoder.next_frame().map_err(|e| UrError::Rtde {
                context: format!("RTDE stream from {}", self.addr),
                cause: e,
            })? {
                if f.kind == kind::TEXT_MESSAGE {
                    if let Ok(Reply::Text(t)) = decode_reply(f.kind, f.payload, self.version) {
                        keep_text(&mut self.texts, &mut self.texts_dropped, t);
                    }
                    continue;
                }
                if f.kind != want {
                    continue;
                }
                let r =
                    decode_reply(f.kind, f.payload, self.version).map_err(|e| UrError::Rtde {
                        context: format!("reply from {}", self.addr),
                        cause: e,
                    })?;
                return pick(r).ok_or_else(|| UrError::Refused {
                    what: format!("reply '{}'", char::from(want)),
                });
            }
            self.fill(deadline, &format!("RTDE reply '{}'", char::from(want)))?;
        }
    }

    fn fill(&mut self, deadline: Instant, what: &str) -> Result<(), UrError> {
        let now = Instant::now();
        if now >= deadline {
            return Err(UrError::Timeout {
                what: format!("{what} from {}", self.addr),
                ms: self.reply_timeout.as_millis(),
            });
        }
        self.stream
            .set_read_timeout(Some((deadline - now).max(Duration::from_millis(1))))
            .map_err(|e| UrError::io("setting a read timeout", e))?;
        match self.stream.read(&mut self.read_buf[..]) {
            Ok(0) => Err(UrError::Closed {
                what: format!("RTDE at {}", self.addr),
            }),
            Ok(n) => {
                self.decoder.push(&self.read_buf[..n]);
                Ok(())
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                Err(UrError::Timeout {
                    what: format!("{what} from {}", self.addr),
                    ms: self.reply_timeout.as_millis(),
                })
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(()),
            Err(e) => Err(UrError::io(format!("reading RTDE from {}", self.addr), e)),
        }
    }
}

fn keep_text(texts: &mut Vec<TextMessage>, dropped: &mut u64, t: TextMessage) {
    if texts.len() >= MAX_TEXTS {
        texts.remove(0);
        *dropped += 1;
    }
    texts.push(t);
}
