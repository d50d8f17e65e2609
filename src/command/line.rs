//! The line buffer: serial bytes into command lines.

use super::error::Error;
use super::MAX_LINE;

/// Collects bytes from the serial port into lines of at most [`MAX_LINE`] bytes.
/// An overlong line is dropped whole and reported once, at its end.
#[derive(Debug, Clone)]
pub struct LineBuffer {
    buf: [u8; MAX_LINE + 1],
    len: usize,
    overflow: bool,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_LINE + 1],
            len: 0,
            overflow: false,
        }
    }

    /// Adds one byte; at `\n` returns the completed line (without `\n`), or
    /// [`Error::LineTooLong`] if it did not fit.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], Error>> {
        if byte == b'\n' {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.overflow) {
                return Some(Err(Error::LineTooLong));
            }
            return Some(Ok(self.buf.get(..len).unwrap_or(&[])));
        }
        match self.buf.get_mut(self.len) {
            Some(slot) if !self.overflow => {
                *slot = byte;
                self.len += 1;
            }
            _ => {
                self.overflow = true;
                self.len = 0;
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_buffer_splits_lines_and_rejects_long_ones() {
        let mut lb = LineBuffer::new();
        let mut lines = std::vec::Vec::new();
        for &b in b"ping\r\nget kp\n".iter() {
            if let Some(l) = lb.push(b) {
                lines.push(l.map(|l| l.to_vec()));
            }
        }
        assert_eq!(lines, vec![Ok(b"ping\r".to_vec()), Ok(b"get kp".to_vec())]);
        for _ in 0..MAX_LINE + 5 {
            assert!(lb.push(b'x').is_none());
        }
        assert_eq!(lb.push(b'\n'), Some(Err(Error::LineTooLong)));
        // The next line is fine again.
        for &b in b"ping" {
            lb.push(b);
        }
        assert_eq!(lb.push(b'\n'), Some(Ok(&b"ping"[..])));
    }
}
