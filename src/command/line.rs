//! The line buffer: serial bytes into command lines.

use super::error::Error;
use super::MAX_LINE;

/// Collects bytes from the serial port into lines of at most [`MAX_LINE`] bytes (plus a
/// `\r`). An overlong line is dropped whole and reported once, at its end. The bytes sit in
/// a `heapless::Vec` (the design card's fixed-capacity collections).
#[derive(Debug, Clone)]
pub struct LineBuffer {
    buf: heapless::Vec<u8, { MAX_LINE + 1 }>,
    overflow: bool,
    /// The last call returned a completed line from `buf`: empty it before the next byte.
    done: bool,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    pub const fn new() -> Self {
        Self {
            buf: heapless::Vec::new(),
            overflow: false,
            done: false,
        }
    }

    /// Adds one byte; at `\n` returns the completed line (without `\n`), or
    /// [`Error::LineTooLong`] if it did not fit.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], Error>> {
        if core::mem::take(&mut self.done) {
            self.buf.clear();
        }
        if byte == b'\n' {
            self.done = true;
            if core::mem::take(&mut self.overflow) {
                return Some(Err(Error::LineTooLong));
            }
            return Some(Ok(self.buf.as_slice()));
        }
        if self.overflow || self.buf.push(byte).is_err() {
            self.overflow = true;
            self.buf.clear();
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
