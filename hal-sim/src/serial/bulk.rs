//! The recorder's frames over the framed binary transfer (`rec bin <start> <count>`): the
//! firmware answers `ok rec bin <frames> <packets>`, then that many COBS packets, each
//! checked by its CRC-32 ([`piezo_core::bulk`]). A packet that fails any check (framing,
//! checksum, header, a frame range other than asked for), a reply line that is not the one
//! expected, or packets that never come mark their frames damaged: the link is drained, and
//! the damaged frames are asked for again, up to [`MAX_ROUNDS`] times. Nothing damaged is
//! ever taken as data; a transfer that stays damaged fails.
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use piezo_core::bulk::{decode, FRAMES_PER_PACKET};
use piezo_core::command::{Command, RecCmd};

use super::client::{parse_line, Line};
use super::lines::checked_line;
use super::{Client, SerialError};

/// Frames asked for per `rec bin` command.
pub const REQUEST_FRAMES: usize = 4096;
/// Requests of the same damaged frames before the transfer fails.
pub const MAX_ROUNDS: usize = 8;

/// What a transfer took.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BulkStats {
    pub frames: usize,
    /// Packets accepted.
    pub packets: usize,
    /// Packets, reply lines or waits refused as damaged (their frames asked for again).
    pub damaged: usize,
    /// `rec bin` commands sent.
    pub requests: usize,
    /// Bytes received for the accepted packets (framing included).
    pub bytes: usize,
    pub seconds: f64,
}

impl BulkStats {
    /// Frames per second of wall-clock time.
    pub fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }
}

/// Frames `start .. start + count` of a finished capture of `channels` channels.
pub fn read_bin(
    c: &mut Client,
    start: usize,
    count: usize,
    channels: usize,
) -> Result<(Vec<Vec<f64>>, BulkStats)> {
    let t0 = Instant::now();
    let mut frames: Vec<Option<Vec<f64>>> = vec![None; count];
    let mut st = BulkStats::default();
    for round in 0.. {
        let missing = missing_runs(&frames);
        if missing.is_empty() {
            break;
        }
        if round == MAX_ROUNDS {
            let (s, n) = missing[0];
            bail!(
                "rec bin: frames {}..{} still damaged after {MAX_ROUNDS} requests ({} damaged \
                 packets in all); nothing was taken from them",
                start + s,
                start + s + n,
                st.damaged
            );
        }
        for (s, n) in missing {
            let mut at = s;
            while at < s + n {
                let k = REQUEST_FRAMES.min(s + n - at);
                let clean = request(c, start, at, k, channels, &mut frames, &mut st)?;
                if !clean {
                    st.damaged += 1;
                    drain(c)?;
                }
                at += k;
            }
        }
    }
    st.frames = count;
    st.seconds = t0.elapsed().as_secs_f64();
    Ok((
        frames.into_iter().map(|f| f.unwrap_or_default()).collect(),
        st,
    ))
}

/// Runs of frames not yet received: (first, length).
fn missing_runs(frames: &[Option<Vec<f64>>]) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        if f.is_none() {
            match runs.last_mut() {
                Some((s, n)) if *s + *n == i => *n += 1,
                _ => runs.push((i, 1)),
            }
        }
    }
    runs
}

/// One `rec bin` request for frames `base + at .. + k`: true when its reply line and every
/// packet were whole (frames of good packets are kept either way).
fn request(
    c: &mut Client,
    base: usize,
    at: usize,
    k: usize,
    channels: usize,
    frames: &mut [Option<Vec<f64>>],
    st: &mut BulkStats,
) -> Result<bool> {
    let cmd = Command::Rec(RecCmd::Bin {
        start: base + at,
        count: k,
    });
    let line = checked_line(&cmd)?;
    st.requests += 1;
    c.send_line(&line)?;
    let reply = match c.read_line(&line) {
        Ok(l) => l,
        Err(SerialError::Timeout { .. } | SerialError::BadReply { .. }) => return Ok(false),
        Err(e) => return Err(e.into()),
    };
    let packets = match parse_line(&reply) {
        Line::Ok(d) => match parse_bin_reply(&d, k) {
            Some(p) => p,
            None => return Ok(false),
        },
        // A refusal names a numbered error: the firmware's answer, not damage.
        Line::Err {
            code: Some(code),
            message,
        } if reply.is_ascii() && piezo_core::command::Error::from_code(code).is_some() => {
            return Err(SerialError::Firmware {
                command: line,
                code: Some(code),
                message,
            }
            .into())
        }
        _ => return Ok(false),
    };
    let mut clean = true;
    for _ in 0..packets {
        let bytes = match c.read_packet(&line) {
            Ok(b) => b,
            Err(SerialError::Timeout { .. } | SerialError::BadReply { .. }) => return Ok(false),
            Err(e) => return Err(e.into()),
        };
        let Ok(p) = decode(&bytes) else {
            st.damaged += 1;
            clean = false;
            continue;
        };
        let first = p.start as usize;
        let inside = first >= base + at && first + p.count <= base + at + k;
        if p.channels != channels || !inside {
            st.damaged += 1;
            clean = false;
            continue;
        }
        for j in 0..p.count {
            if let (Some(slot), Some(v)) = (frames.get_mut(first - base + j), p.frame(j)) {
                *slot = Some(v.iter().map(|&x| shortest(x)).collect());
            }
        }
        st.packets += 1;
        st.bytes += bytes.len() + 1;
    }
    Ok(clean)
}

/// `x` as the f64 of its shortest decimal form: the value `rec read` prints for it, so a
/// binary and a text capture give the same CSV.
pub fn shortest(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

/// `rec bin <k> <packets>` with `k` the frames asked for: the packets to read.
fn parse_bin_reply(details: &str, k: usize) -> Option<usize> {
    let mut w = details.split(' ');
    let (Some("rec"), Some("bin"), Some(n), Some(p), None) =
        (w.next(), w.next(), w.next(), w.next(), w.next())
    else {
        return None;
    };
    let (n, p): (usize, usize) = (n.parse().ok()?, p.parse().ok()?);
    (n == k && p == k.div_ceil(FRAMES_PER_PACKET)).then_some(p)
}

/// After damage: drop what is still arriving of the broken transfer (until the link is
/// quiet), then get in step again (`ping` ... `ok pong`).
fn drain(c: &mut Client) -> Result<()> {
    c.discard_until_quiet(Duration::from_millis(200));
    let mut last = None;
    for _ in 0..3 {
        match c.sync() {
            Ok(_) => return Ok(()),
            Err(e) => last = Some(e),
        }
        c.discard_until_quiet(Duration::from_millis(200));
    }
    match last {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_runs_and_reply_parsing() {
        let f = vec![None, Some(vec![]), None, None, Some(vec![]), None];
        assert_eq!(missing_runs(&f), vec![(0, 1), (2, 2), (5, 1)]);
        assert_eq!(parse_bin_reply("rec bin 100 4", 100), Some(4));
        assert_eq!(parse_bin_reply("rec bin 100 4", 99), None);
        assert_eq!(parse_bin_reply("rec bin 100 3", 100), None);
        assert_eq!(parse_bin_reply("rec bjn 100 4", 100), None);
        assert_eq!(parse_bin_reply("rec bin 100 4 x", 100), None);
    }
}
