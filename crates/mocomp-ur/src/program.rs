//! mocomp's resident control program and its register protocol.
//!
//! The client uploads [`script`] to the controller's script port (30003) once per connection,
//! after ending (EXIT) a program of ours it finds still running, which would otherwise answer
//! for the new one; a program the watchdog stops before the client's first feed reaches it is
//! uploaded again, twice at most.
//! The program then runs at the controller rate and takes commands from RTDE input registers in
//! the **external-client range 24–47** (registers 0–23 stay free for fieldbus/PLC use and for
//! ur_rtde, so both can run side by side).
//!
//! # Register protocol (version 1)
//!
//! Inputs (client → program), all in one input recipe sent as one data package per command:
//!
//! | register | meaning |
//! |---|---|
//! | `input_int_register_24` | command: 0 none, 1 SERVOJ, 2 MOVEJ, 3 SPEEDJ, 4 STOPJ, 5 EXIT, 6 ZERO_FT, 7 FREEDRIVE |
//! | `input_int_register_25` | sequence number; the client increments it with every new command. The RTDE watchdog watches this register. |
//! | `input_double_register_24..29` | joint positions q (SERVOJ, MOVEJ) or velocities qd (SPEEDJ), rad, rad/s |
//! | `input_double_register_30` | SERVOJ `t` (s); MOVEJ speed (rad/s); SPEEDJ and STOPJ acceleration (rad/s²) |
//! | `input_double_register_31` | SERVOJ `lookahead_time` (s); MOVEJ acceleration (rad/s²) |
//! | `input_double_register_32` | SERVOJ `gain` |
//!
//! Outputs (program → client):
//!
//! | register | meaning |
//! |---|---|
//! | `output_int_register_24` | program mode: 0 not running, 1 idle, 2 servoing, 3 moving (MOVEJ), 4 speed control, 5 stopping, 6 free-drive |
//! | `output_int_register_25` | sequence number of the newest command taken |
//! | `output_int_register_26` | protocol id [`PROTOCOL_ID`] while the program runs (tells our program from others) |
//! | `output_int_register_27` | sequence number of the newest MOVEJ completed |
//!
//! Semantics: SERVOJ, SPEEDJ and FREEDRIVE are *level* commands: every cycle the program servoes
//! to (or runs at) the newest target in the registers, or keeps the arm in free-drive
//! (`freedrive_mode()`: a hand moves it); any other command ends free-drive
//! (`end_freedrive_mode()`), and so does the watchdog when the client falls silent, which makes
//! the client's keep-alive free-drive's dead-man switch. MOVEJ, STOPJ, EXIT and ZERO_FT (`zero_ftsensor()`,
//! e-Series only: a CB3 program logs that it has no sensor) are *edge* commands: they
//! run once, when their sequence number is new. A client may therefore resend its last package
//! at any time (a keep-alive) without repeating a move. The program sets an RTDE watchdog on
//! `input_int_register_25` with action `stop`: when no package arrives for `1 / watchdog_hz`
//! seconds, the controller stops the program and the arm decelerates (a PC that hangs or
//! disconnects cannot leave the arm moving).
//!
//! The simulator (`mocomp-ursim`) recognises this program by its first line and the
//! `# mocomp-control-protocol 1` marker and runs the same protocol natively.

/// The first line of the program.
pub const PROGRAM_HEADER: &str = "def mocomp_control():";
/// The marker line that names the protocol version.
pub const PROTOCOL_MARKER: &str = "# mocomp-control-protocol 1";
/// Written to `output_int_register_26` while the program runs ("mc" and version 1).
pub const PROTOCOL_ID: i32 = 0x6d63_0001;

/// Command codes (`input_int_register_24`).
pub mod cmd {
    /// No command (hold what runs).
    pub const NONE: i32 = 0;
    /// Servo to the target (level).
    pub const SERVOJ: i32 = 1;
    /// Point-to-point joint move (edge).
    pub const MOVEJ: i32 = 2;
    /// Joint speed (level).
    pub const SPEEDJ: i32 = 3;
    /// Decelerate to standstill (edge).
    pub const STOPJ: i32 = 4;
    /// End the program after stopping (edge).
    pub const EXIT: i32 = 5;
    /// Zero the force/torque sensor, `zero_ftsensor()` (edge; e-Series).
    pub const ZERO_FT: i32 = 6;
    /// Free-drive, `freedrive_mode()`, while it is sent (level).
    pub const FREEDRIVE: i32 = 7;
}

/// Program modes (`output_int_register_24`): the interface's [`mocomp_robot::mode`], which this
/// program reports.
pub use mocomp_robot::mode;

/// The first register of the protocol (external-client range).
pub const REGISTER_BASE: u32 = 24;

/// The input recipe's variables, in order.
pub const INPUT_NAMES: [&str; 11] = [
    "input_int_register_24",
    "input_int_register_25",
    "input_double_register_24",
    "input_double_register_25",
    "input_double_register_26",
    "input_double_register_27",
    "input_double_register_28",
    "input_double_register_29",
    "input_double_register_30",
    "input_double_register_31",
    "input_double_register_32",
];

/// The output registers the client reads, in order.
pub const OUTPUT_REGISTER_NAMES: [&str; 4] = [
    "output_int_register_24",
    "output_int_register_25",
    "output_int_register_26",
    "output_int_register_27",
];

/// The program text, with the watchdog's minimum frequency (Hz); `ft_sensor`: the arm has a
/// force/torque sensor (an e-Series), so ZERO_FT calls `zero_ftsensor()` (a CB3's URScript has
/// no such function, and a program that names it would not compile there).
///
/// Written against the URScript manual (`servoj`, `speedj`, `movej`, `stopj`,
/// `rtde_set_watchdog`, `read_input_integer_register`, `read_input_float_register`,
/// `write_output_integer_register`, threads). It has run against the simulator's native
/// emulation only: no physical controller was available to this project yet.
pub fn script(watchdog_hz: f64, ft_sensor: bool) -> String {
    let zero_ft = if ft_sensor {
        "zero_ftsensor()"
    } else {
        "textmsg(\"mocomp: this arm has no force/torque sensor to zero\")"
    };
    format!(
        r#"{PROGRAM_HEADER}
  {PROTOCOL_MARKER}
  textmsg("mocomp control program started")
  global servo_q = get_actual_joint_positions()
  global servo_t = 0.008
  global servo_lookahead = 0.1
  global servo_gain = 300
  global speed_qd = [0, 0, 0, 0, 0, 0]
  global speed_a = 1.0
  global move_q = servo_q
  global move_v = 1.05
  global move_a = 1.4
  global move_seq = 0
  global prog_mode = 1
  global last_seq = read_input_integer_register(25)
  global thrd = 0
  def read_vector():
    return [read_input_float_register(24), read_input_float_register(25), read_input_float_register(26), read_input_float_register(27), read_input_float_register(28), read_input_float_register(29)]
  end
  thread servo_thread():
    while True:
      servoj(servo_q, 0, 0, servo_t, servo_lookahead, servo_gain)
    end
  end
  thread speed_thread():
    while True:
      speedj(speed_qd, speed_a, servo_t)
    end
  end
  thread move_thread():
    movej(move_q, a=move_a, v=move_v)
    write_output_integer_register(27, move_seq)
    prog_mode = 1
  end
  def stop_motion():
    if thrd != 0:
      kill thrd
      thrd = 0
    end
  end
  write_output_integer_register(27, 0)
  write_output_integer_register(26, {PROTOCOL_ID})
  rtde_set_watchdog("input_int_register_25", {watchdog_hz:.3}, "stop")
  while True:
    cmd = read_input_integer_register(24)
    seq = read_input_integer_register(25)
    if prog_mode == 6 and cmd != 7:
      end_freedrive_mode()
      prog_mode = 1
    end
    if cmd == 1:
      servo_q = read_vector()
      servo_t = read_input_float_register(30)
      servo_lookahead = read_input_float_register(31)
      servo_gain = read_input_float_register(32)
      if prog_mode != 2:
        stop_motion()
        thrd = run servo_thread()
        prog_mode = 2
      end
    elif cmd == 3:
      speed_qd = read_vector()
      speed_a = read_input_float_register(30)
      if prog_mode != 4:
        stop_motion()
        thrd = run speed_thread()
        prog_mode = 4
      end
    elif cmd == 7:
      if prog_mode != 6:
        stop_motion()
        freedrive_mode()
        prog_mode = 6
      end
    elif seq != last_seq:
      if cmd == 2:
        stop_motion()
        move_q = read_vector()
        move_v = read_input_float_register(30)
        move_a = read_input_float_register(31)
        move_seq = seq
        prog_mode = 3
        thrd = run move_thread()
      elif cmd == 4:
        stop_motion()
        prog_mode = 5
        stopj(read_input_float_register(30))
        prog_mode = 1
      elif cmd == 5:
        break
      elif cmd == 6:
        {zero_ft}
      end
    end
    last_seq = seq
    write_output_integer_register(25, seq)
    write_output_integer_register(24, prog_mode)
    sync()
  end
  stop_motion()
  stopj(4.0)
  write_output_integer_register(24, 0)
  write_output_integer_register(26, 0)
  textmsg("mocomp control program ended")
end
"#
    )
}

/// Reads the watchdog frequency back out of a program text (what the simulator does with an
/// uploaded program): the `rtde_set_watchdog("input_int_register_25", f, "stop")` line.
pub fn watchdog_hz_in(script: &str) -> Option<f64> {
    let line = script
        .lines()
        .find(|l| l.trim_start().starts_with("rtde_set_watchdog("))?;
    let args = line.split_once('(')?.1.rsplit_once(')')?.0;
    args.split(',').nth(1)?.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_e_series_program_names_zero_ftsensor() {
        assert!(script(25.0, true).contains("\n        zero_ftsensor()\n"));
        let cb3 = script(25.0, false);
        assert!(!cb3.contains("zero_ftsensor"), "{cb3}");
        assert!(cb3.contains("no force/torque sensor"));
    }

    #[test]
    fn program_has_urscript_shape_and_its_parameters() {
        let s = script(25.0, true);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines[0], PROGRAM_HEADER);
        assert_eq!(lines.last().copied(), Some("end"));
        // URScript over a socket: only `def` and the final `end` in column 1.
        for l in &lines[1..lines.len() - 1] {
            assert!(l.is_empty() || l.starts_with(' '), "{l:?}");
        }
        assert!(s.contains(PROTOCOL_MARKER));
        assert!(s.contains(&PROTOCOL_ID.to_string()));
        assert_eq!(watchdog_hz_in(&s), Some(25.0));
        // Balanced blocks: every def/thread/while/if opens one `end`.
        let opens = lines
            .iter()
            .map(|l| l.trim_start())
            .filter(|l| {
                l.starts_with("def ")
                    || l.starts_with("thread ")
                    || l.starts_with("while ")
                    || l.starts_with("if ")
            })
            .count();
        let ends = lines.iter().filter(|l| l.trim() == "end").count();
        assert_eq!(opens, ends);
    }
}
