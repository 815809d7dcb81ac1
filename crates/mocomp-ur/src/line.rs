//! Line-oriented protocols (the dashboard, a script port) read with a bound: a peer that sends
//! an endless line without its `\n` cannot make us allocate without limit.

use std::io::{BufRead, ErrorKind, Read};

/// How reading a line ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineRead {
    /// `line` ends with `\n`.
    Complete,
    /// No `\n` yet (a read timed out, or the bytes so far are part of a line): call again.
    Partial,
    /// The peer closed the connection (`line` holds what came before, if anything).
    Closed,
    /// More than the limit came without a `\n`: the line is not taken.
    TooLong,
}

/// Reads (appending to `line`) up to and including the next `\n`, taking at most `max` bytes
/// in all into `line`. A timeout or an interrupted read is [`LineRead::Partial`]; other I/O
/// errors are returned.
pub fn read_line_bounded<R: BufRead>(
    r: &mut R,
    max: usize,
    line: &mut Vec<u8>,
) -> std::io::Result<LineRead> {
    let room = max.saturating_sub(line.len()) as u64 + 1;
    match r.by_ref().take(room).read_until(b'\n', line) {
        Ok(0) if room > 0 => Ok(LineRead::Closed),
        Ok(_) if line.last() == Some(&b'\n') && line.len() <= max => Ok(LineRead::Complete),
        Ok(_) if line.len() > max => Ok(LineRead::TooLong),
        Ok(_) => Ok(LineRead::Partial),
        Err(e)
            if matches!(
                e.kind(),
                ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
            ) =>
        {
            Ok(LineRead::Partial)
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn lines_are_cut_at_their_end_and_bounded() {
        let mut r: &[u8] = b"Powering on\nnext";
        let mut line = Vec::new();
        assert_eq!(
            read_line_bounded(&mut r, 64, &mut line).unwrap(),
            LineRead::Complete
        );
        assert_eq!(line, b"Powering on\n");
        line.clear();
        assert_eq!(
            read_line_bounded(&mut r, 64, &mut line).unwrap(),
            LineRead::Partial
        );
        assert_eq!(line, b"next");
        assert_eq!(
            read_line_bounded(&mut r, 64, &mut line).unwrap(),
            LineRead::Closed
        );
        // An endless line: refused after the limit, never more read into memory.
        let endless = vec![b'x'; 1 << 20];
        let mut r: &[u8] = &endless;
        let mut line = Vec::new();
        assert_eq!(
            read_line_bounded(&mut r, 4096, &mut line).unwrap(),
            LineRead::TooLong
        );
        assert_eq!(line.len(), 4097);
        // A line of exactly the limit, its \n included, is taken.
        let exact = [vec![b'y'; 4095], vec![b'\n']].concat();
        let mut r: &[u8] = &exact;
        let mut line = Vec::new();
        assert_eq!(
            read_line_bounded(&mut r, 4096, &mut line).unwrap(),
            LineRead::Complete
        );
    }
}
