//! The programs the simulator runs natively, mocomp's and ur_rtde's, recognised from their text,
//! with the RTDE watchdog.

use super::*;

#[derive(Debug, Clone, Copy)]
pub(super) struct MocompProgram {
    pub(super) last_seq: i32,
    pub(super) mode: i32,
    pub(super) move_seq: i32,
    pub(super) blocked_stop: bool,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct RtdeProgram {
    pub(super) off_int: usize,
    pub(super) off_double: usize,
    pub(super) executing: bool,
    /// Inside a blocking `process_cmd` until the motion ends (then DONE is signalled).
    pub(super) blocking: bool,
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Program {
    None,
    Mocomp(MocompProgram),
    UrRtde(RtdeProgram),
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Watchdog {
    pub(super) register: usize,
    pub(super) hz: f64,
    pub(super) since_s: f64,
    /// The client's first feed comes too late: the program stops at its first cycle.
    pub(super) late: bool,
}

/// A program text the simulator recognises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProgramKind {
    /// mocomp's control program (its watchdog, Hz).
    Mocomp {
        /// Watchdog frequency from the program text.
        watchdog_hz: f64,
    },
    /// ur_rtde's `rtde_control` script, with its register offsets.
    UrRtde {
        /// Integer register offset (0 or 24).
        off_int: usize,
        /// Double register offset (0 or 24).
        off_double: usize,
    },
    /// Any other program: the simulator does not interpret URScript.
    Unsupported,
}

/// Classifies a complete program text (a `def …():` … `end` block).
pub fn classify_program(text: &str) -> ProgramKind {
    let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    if first.trim_end() == mp::PROGRAM_HEADER && text.contains(mp::PROTOCOL_MARKER) {
        return ProgramKind::Mocomp {
            watchdog_hz: mp::watchdog_hz_in(text).unwrap_or(0.0),
        };
    }
    if first.starts_with("def rtde_control():") && text.contains("RTDE Control Script") {
        let offset = |key: &str| {
            text.lines()
                .find_map(|l| l.split_once(key).map(|(_, r)| r))
                .and_then(|r| r.trim_start_matches([' ', '=']).split_whitespace().next())
                .and_then(|n| n.parse::<usize>().ok())
                .filter(|n| *n == 0 || *n == 24)
                .unwrap_or(0)
        };
        return ProgramKind::UrRtde {
            off_int: offset("reg_offset_int"),
            off_double: offset("reg_offset_float"),
        };
    }
    ProgramKind::Unsupported
}

impl Controller {
    /// Loads a complete program text received on a script port (stopping any program running).
    pub fn load_program(&mut self, text: &str) {
        let kind = classify_program(text);
        if !matches!(self.program, Program::None) || self.runtime == RuntimeState::Playing {
            self.stop_program("a new program was sent".into());
        }
        if !self.can_move() {
            self.record_event(format!(
                "program not started: robot mode {}, safety mode {}",
                self.robot_mode, self.safety_mode
            ));
            return;
        }
        match kind {
            ProgramKind::Mocomp { watchdog_hz } => {
                self.program = Program::Mocomp(MocompProgram {
                    last_seq: self.regs.in_int[25],
                    mode: mmode::IDLE,
                    move_seq: 0,
                    blocked_stop: false,
                });
                self.regs.out_int[26] = mp::PROTOCOL_ID;
                self.regs.out_int[27] = 0;
                self.regs.out_int[24] = mmode::IDLE;
                self.regs.out_int[25] = self.regs.in_int[25];
                let late = self.late_first_feeds > 0;
                self.late_first_feeds = self.late_first_feeds.saturating_sub(1);
                self.watchdog = (watchdog_hz > 0.0).then_some(Watchdog {
                    register: 25,
                    hz: watchdog_hz,
                    since_s: self.time_s,
                    late,
                });
                self.record_event(format!(
                    "mocomp control program started (watchdog {watchdog_hz} Hz)"
                ));
            }
            ProgramKind::UrRtde {
                off_int,
                off_double,
            } => {
                self.program = Program::UrRtde(RtdeProgram {
                    off_int,
                    off_double,
                    executing: false,
                    blocking: false,
                });
                self.regs.out_int[off_int] = 1;
                self.watchdog = None;
                self.record_event(format!(
                    "ur_rtde control script started (register offset {off_int})"
                ));
            }
            ProgramKind::Unsupported => {
                let first = text.lines().next().unwrap_or("").chars().take(60);
                self.record_event(format!(
                    "program {:?} not run: the simulator runs only mocomp's and ur_rtde's \
                     control programs",
                    first.collect::<String>()
                ));
                return;
            }
        }
        self.runtime = RuntimeState::Playing;
    }

    /// Whether the RTDE watchdog stops the program at the next cycle unless its register is
    /// updated before it.
    pub fn watchdog_due(&self) -> bool {
        let next = (self.tick + 1) as f64 * self.period;
        self.watchdog_silence_at(next).is_some()
    }

    /// How long the watched register has gone without an update at controller time `t`, s,
    /// when that is past the watchdog's limit (with the watchdog).
    fn watchdog_silence_at(&self, t: f64) -> Option<(f64, Watchdog)> {
        let w = self.watchdog?;
        let silence = t - self.regs.in_int_updated_s[w.register].max(w.since_s);
        (silence > 1.0 / w.hz + 1e-9).then_some((silence, w))
    }

    /// The client's packages are waiting unread on the controller's own socket: the client was
    /// not silent, the simulator's reader was late (a real controller reads its inputs every
    /// cycle). The watchdog's silence starts again from now.
    pub fn note_unread_input(&mut self) {
        if let Some(w) = self.watchdog.as_mut() {
            w.since_s = w.since_s.max(self.time_s);
        }
    }

    /// The next `programs` mocomp control programs find their client late: each is stopped by
    /// its watchdog at its first cycle, before any command of the client's reaches it, as when
    /// a busy PC holds the client back between the upload and its first feed for longer than
    /// the watchdog allows. A test's way to make that race happen every time.
    pub fn hold_back_first_feeds(&mut self, programs: u32) {
        self.late_first_feeds = programs;
    }

    pub(super) fn check_watchdog(&mut self) {
        if let Some(w) = self.watchdog.filter(|w| w.late) {
            self.stop_program(format!(
                "RTDE watchdog: input_int_register_{} not updated within {:.0} ms of the \
                 program's start (the client's first feed held back)",
                w.register,
                1e3 / w.hz
            ));
            return;
        }
        if let Some((silence, w)) = self.watchdog_silence_at(self.time_s) {
            self.stop_program(format!(
                "RTDE watchdog: input_int_register_{} not updated for {:.0} ms (limit {:.0} ms)",
                w.register,
                silence * 1e3,
                1e3 / w.hz
            ));
        }
    }

    pub(super) fn run_program(&mut self) {
        if !self.can_move() {
            return;
        }
        match self.program {
            Program::None => {}
            Program::Mocomp(p) => self.run_mocomp(p),
            Program::UrRtde(p) => self.run_ur_rtde(p),
        }
    }

    pub(super) fn run_mocomp(&mut self, mut p: MocompProgram) {
        if p.blocked_stop {
            return; // inside a blocking stopj
        }
        let b = mp::REGISTER_BASE as usize;
        let command = self.regs.in_int[b];
        let seq = self.regs.in_int[b + 1];
        if p.mode == mmode::FREEDRIVE && command != mcmd::FREEDRIVE {
            // end_freedrive_mode(): the arm stops where the hand left it.
            self.motion = Motion::Stop {
                decel: self.config.stop_decel,
            };
            p.mode = mmode::IDLE;
            self.record_event("free-drive ended".into());
        }
        let d = |k: usize| self.regs.in_double[b + k];
        match command {
            mcmd::FREEDRIVE if p.mode != mmode::FREEDRIVE => {
                self.motion = Motion::Freedrive;
                p.mode = mmode::FREEDRIVE;
                self.record_event("free-drive started".into());
            }
            mcmd::FREEDRIVE => {}
            mcmd::SERVOJ => {
                if !self.start_servo(self.read_q(b), d(6), d(7), d(8)) {
                    return;
                }
                p.mode = mmode::SERVO;
            }
            mcmd::SPEEDJ => {
                if !self.start_speed(self.read_q(b), d(6)) {
                    return;
                }
                p.mode = mmode::SPEED;
            }
            _ if seq != p.last_seq => match command {
                mcmd::MOVEJ => {
                    if !self.start_move(self.read_q(b), d(6), d(7)) {
                        return;
                    }
                    p.move_seq = seq;
                    p.mode = mmode::MOVING;
                }
                mcmd::STOPJ => {
                    let a = if d(6).is_finite() && d(6) > 0.0 {
                        d(6)
                    } else {
                        4.0
                    };
                    self.motion = Motion::Stop { decel: a };
                    p.mode = mmode::STOPPING;
                    p.blocked_stop = true;
                }
                mcmd::ZERO_FT => self.zero_ftsensor(),
                mcmd::EXIT => {
                    self.regs.out_int[b] = mmode::NOT_RUNNING;
                    self.regs.out_int[b + 2] = 0;
                    self.regs.out_int[b + 1] = seq;
                    self.stop_program("the control program received EXIT".into());
                    return;
                }
                _ => {}
            },
            _ => {}
        }
        p.last_seq = seq;
        self.regs.out_int[b + 1] = seq;
        self.regs.out_int[b] = p.mode;
        self.program = Program::Mocomp(p);
    }

    pub(super) fn run_ur_rtde(&mut self, mut p: RtdeProgram) {
        if p.blocking {
            return; // inside process_cmd until the motion ends
        }
        let oi = p.off_int;
        let command = self.regs.in_int[oi];
        const REALTIME: [i32; 11] = [6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66];
        if REALTIME.contains(&command) || (66..=71).contains(&command) {
            if !self.process_ur_rtde(&mut p, command) {
                return;
            }
            self.regs.out_int[oi] = 1;
        } else if command == 0 {
            p.executing = false;
            self.regs.out_int[oi] = 1;
        } else if !p.executing {
            if !self.process_ur_rtde(&mut p, command) {
                return;
            }
            p.executing = true;
            if !p.blocking {
                self.regs.out_int[oi] = 2;
            }
        }
        self.program = Program::UrRtde(p);
    }

    /// One ur_rtde command; false when the program ended.
    pub(super) fn process_ur_rtde(&mut self, p: &mut RtdeProgram, command: i32) -> bool {
        let od = p.off_double;
        let d = |k: usize| self.regs.in_double[(od + k).min(NREG - 1)];
        let i1 = self.regs.in_int[(p.off_int + 1).min(NREG - 1)];
        match command {
            1 => {
                if !self.start_move(self.read_q(od), d(6), d(7)) {
                    return false;
                }
                if i1 == 0 {
                    p.blocking = true;
                }
            }
            // moveL (a pose) and moveL_FK (joints, their pose)
            3 | 4 => {
                let target = self.read_q(od);
                let goal = if command == 3 {
                    mocomp_geom::iso_from_ur_pose(&target).ok()
                } else {
                    target
                        .iter()
                        .all(|x| x.is_finite())
                        .then(|| self.arm.fk(&target))
                };
                let Some(goal) = goal else {
                    self.stop_program("movel: the target is not a pose".into());
                    return false;
                };
                if !self.start_linear(goal, d(6), d(7)) {
                    return false;
                }
                if i1 == 0 {
                    p.blocking = true;
                }
            }
            9 => {
                if !self.start_speed(self.read_q(od), d(6)) {
                    return false;
                }
            }
            11 => {
                if !self.start_servo(self.read_q(od), d(8), d(9), d(10)) {
                    return false;
                }
            }
            15 | 16 | 34 => {
                let a = if d(0).is_finite() && d(0) > 0.0 {
                    d(0)
                } else {
                    10.0
                };
                self.motion = Motion::Stop { decel: a };
                if command != 34 || i1 == 0 {
                    p.blocking = true;
                }
            }
            35 => {
                let hz = d(0);
                if hz.is_finite() && hz > 0.0 {
                    self.watchdog = Some(Watchdog {
                        register: p.off_int,
                        hz,
                        since_s: self.time_s,
                        late: false,
                    });
                }
            }
            26 => self.regs.out_double[od] = self.period,
            // zeroFtSensor
            8 => self.zero_ftsensor(),
            255 => {
                self.record_event("ur_rtde: Received stop script!".into());
                self.stop_program("ur_rtde STOP_SCRIPT".into());
                return false;
            }
            other => {
                // A simulator refuses what it does not do: acknowledging a command without
                // doing it would let a client believe it was done.
                self.stop_program(format!(
                    "ur_rtde command {other} is not emulated by this simulator: the program is \
                     stopped (a real controller would have run it)"
                ));
                return false;
            }
        }
        true
    }

    pub(super) fn finish_program_waits(&mut self) {
        let idle = matches!(self.motion, Motion::Idle);
        match &mut self.program {
            Program::UrRtde(p) => {
                if p.blocking && idle {
                    p.blocking = false;
                    let oi = p.off_int;
                    self.regs.out_int[oi] = 2;
                }
            }
            Program::Mocomp(p) => {
                let b = mp::REGISTER_BASE as usize;
                if p.blocked_stop && idle {
                    p.blocked_stop = false;
                    p.mode = mmode::IDLE;
                    self.regs.out_int[b] = mmode::IDLE;
                    self.regs.out_int[b + 1] = p.last_seq;
                }
                if p.mode == mmode::MOVING && idle {
                    p.mode = mmode::IDLE;
                    self.regs.out_int[b] = mmode::IDLE;
                    self.regs.out_int[b + 3] = p.move_seq;
                }
            }
            Program::None => {}
        }
    }
}
