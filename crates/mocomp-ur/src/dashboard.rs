//! The dashboard client (TCP 29999): one command per line, one reply line each, after a welcome
//! line. Replies are checked against what the controller answers on success (URCL's G5 dashboard
//! client, ur_rtde); anything else is an error naming the command and the reply.

use crate::error::UrError;
use crate::line::{LineRead, read_line_bounded};
use mocomp_robot::{RobotMode, SafetyMode};
use std::io::{BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

/// The standard dashboard port.
pub const DASHBOARD_PORT: u16 = 29999;

/// The longest reply line taken, bytes (the controller's longest is a few hundred).
pub const MAX_LINE: usize = 4096;

/// A connected dashboard client.
#[derive(Debug)]
pub struct Dashboard {
    reader: BufReader<TcpStream>,
    writer: TcpStream,
    addr: SocketAddr,
    welcome: String,
}

impl Dashboard {
    /// Connects and reads the welcome line (`Connected: Universal Robots Dashboard Server`).
    pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<Dashboard, UrError> {
        let ctx = || format!("dashboard at {addr}");
        let s = TcpStream::connect_timeout(&addr, timeout).map_err(|e| UrError::io(ctx(), e))?;
        s.set_read_timeout(Some(timeout))
            .map_err(|e| UrError::io(ctx(), e))?;
        s.set_nodelay(true).map_err(|e| UrError::io(ctx(), e))?;
        let writer = s.try_clone().map_err(|e| UrError::io(ctx(), e))?;
        let mut d = Dashboard {
            reader: BufReader::new(s),
            writer,
            addr,
            welcome: String::new(),
        };
        d.welcome = d.line("welcome")?;
        if !d.welcome.contains("Dashboard Server") {
            return Err(UrError::Dashboard {
                command: "(connect)".into(),
                reply: d.welcome,
                expected: "Connected: Universal Robots Dashboard Server",
            });
        }
        Ok(d)
    }

    /// The welcome line.
    pub fn welcome(&self) -> &str {
        &self.welcome
    }

    /// Sends one command and returns the reply line (without the line end).
    pub fn command(&mut self, command: &str) -> Result<String, UrError> {
        self.writer
            .write_all(format!("{command}\n").as_bytes())
            .map_err(|e| UrError::io(format!("dashboard at {}", self.addr), e))?;
        self.line(command)
    }

    /// One reply line, at most [`MAX_LINE`] bytes (a longer one is refused, not read on), text
    /// taken lossily (a reply is compared, never executed).
    fn line(&mut self, what: &str) -> Result<String, UrError> {
        let mut s = Vec::new();
        match read_line_bounded(&mut self.reader, MAX_LINE, &mut s) {
            Ok(LineRead::Complete) => Ok(String::from_utf8_lossy(&s)
                .trim_end_matches(['\n', '\r'])
                .to_string()),
            Ok(LineRead::Closed) => Err(UrError::Closed {
                what: format!("dashboard at {}", self.addr),
            }),
            Ok(LineRead::TooLong) => Err(UrError::Dashboard {
                command: what.into(),
                reply: format!("a line of more than {MAX_LINE} bytes"),
                expected: "one reply line",
            }),
            Ok(LineRead::Partial) => Err(UrError::Timeout {
                what: format!("the dashboard's answer to {what:?}"),
                ms: 0,
            }),
            Err(e) => Err(UrError::io(format!("dashboard at {}", self.addr), e)),
        }
    }

    fn expect(&mut self, command: &str, ok: &'static str) -> Result<String, UrError> {
        let reply = self.command(command)?;
        if reply.starts_with(ok) {
            Ok(reply)
        } else {
            Err(UrError::Dashboard {
                command: command.into(),
                reply,
                expected: ok,
            })
        }
    }

    /// `power on`.
    pub fn power_on(&mut self) -> Result<(), UrError> {
        self.expect("power on", "Powering on").map(drop)
    }

    /// `power off`.
    pub fn power_off(&mut self) -> Result<(), UrError> {
        self.expect("power off", "Powering off").map(drop)
    }

    /// `brake release`.
    pub fn brake_release(&mut self) -> Result<(), UrError> {
        self.expect("brake release", "Brake releasing").map(drop)
    }

    /// `play` (the loaded program).
    pub fn play(&mut self) -> Result<(), UrError> {
        self.expect("play", "Starting program").map(drop)
    }

    /// `stop` (the running program).
    pub fn stop(&mut self) -> Result<(), UrError> {
        self.expect("stop", "Stopped").map(drop)
    }

    /// `unlock protective stop`.
    pub fn unlock_protective_stop(&mut self) -> Result<(), UrError> {
        self.expect("unlock protective stop", "Protective stop releasing")
            .map(drop)
    }

    /// `close safety popup`.
    pub fn close_safety_popup(&mut self) -> Result<(), UrError> {
        self.expect("close safety popup", "closing safety popup")
            .map(drop)
    }

    /// `robotmode`.
    pub fn robot_mode(&mut self) -> Result<RobotMode, UrError> {
        let r = self.expect("robotmode", "Robotmode: ")?;
        let word = r.trim_start_matches("Robotmode: ").trim();
        RobotMode::from_name(word).ok_or(UrError::Dashboard {
            command: "robotmode".into(),
            reply: r.clone(),
            expected: "Robotmode: <mode>",
        })
    }

    /// `safetymode`.
    pub fn safety_mode(&mut self) -> Result<SafetyMode, UrError> {
        let r = self.expect("safetymode", "Safetymode: ")?;
        let word = r.trim_start_matches("Safetymode: ").trim();
        SafetyMode::from_name(word).ok_or(UrError::Dashboard {
            command: "safetymode".into(),
            reply: r.clone(),
            expected: "Safetymode: <mode>",
        })
    }

    /// `is in remote control` (e-Series 5.6+): whether the controller accepts network control.
    pub fn is_in_remote_control(&mut self) -> Result<bool, UrError> {
        let r = self.command("is in remote control")?;
        match r.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            _ => Err(UrError::Dashboard {
                command: "is in remote control".into(),
                reply: r,
                expected: "true or false",
            }),
        }
    }

    /// `PolyscopeVersion` (the reply, e.g. `URSoftware 5.11.1.108318 (Mar 18 2021)`).
    pub fn polyscope_version(&mut self) -> Result<String, UrError> {
        self.expect("PolyscopeVersion", "URSoftware")
    }
}
