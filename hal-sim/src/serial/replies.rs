//! Typed replies: the `ok` details of `get`, `stats`, `rec status`, `rec sel` and the frame
//! lines of `rec read`; a reply that does not parse is a [`SerialError::BadReply`] naming it.
use piezo_core::command::{Command, RecCmd};

use piezo_core::recorder::Signal;

use super::client::{Client, Response};
use super::error::SerialError;
use super::lines::select_line;

/// `get <param>` reply `ok <param> <value>`.
pub fn parse_get(resp: &Response, param: &str) -> Result<f64, String> {
    let mut w = resp.details.split_whitespace();
    match (w.next(), w.next(), w.next()) {
        (Some(p), Some(v), None) if p == param => v
            .parse::<f64>()
            .map_err(|_| format!("value `{v}` is not a number")),
        _ => Err(format!("expected `ok {param} <value>`")),
    }
}

/// Timing counts of `stats`: DWT cycles on the H743, SysTick ticks (25 MHz) under QEMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Stats {
    pub step_min: u32,
    pub step_max: u32,
    pub step_last: u32,
    pub isr_min: u32,
    pub isr_max: u32,
    pub isr_last: u32,
    pub samples: u32,
    pub overruns: u32,
    /// Samples lost entirely (firmware that reports it).
    pub lost: Option<u32>,
    /// The longest start of the control interrupt after its period's trigger, in the same
    /// counts (boards whose counter tells).
    pub late_max: Option<u32>,
    /// While NMPC runs with its solver in a lower-priority task: jobs posted and boundaries
    /// whose plan came too late, since the mode was selected.
    pub nmpc_jobs: Option<u32>,
    pub nmpc_missed: Option<u32>,
}

/// `ok step <min> <max> <last> isr <min> <max> <last> samples <n> overruns <n>`, then
/// `<key> <n>` pairs: `lost`, `late` (`-` where the board cannot tell), `nmpc_jobs`,
/// `nmpc_missed`; keys a newer firmware adds are skipped.
pub fn parse_stats(details: &str) -> Result<Stats, String> {
    let w: Vec<&str> = details.split_whitespace().collect();
    let expect =
        "step <min> <max> <last> isr <min> <max> <last> samples <n> overruns <n> [<key> <n>]...";
    let keys = [(0, "step"), (4, "isr"), (8, "samples"), (10, "overruns")];
    if w.len() < 12 || !w.len().is_multiple_of(2) || keys.iter().any(|&(i, k)| w.get(i) != Some(&k))
    {
        return Err(format!("expected `{expect}`"));
    }
    let n = |i: usize| -> Result<u32, String> {
        let s = w.get(i).copied().unwrap_or("");
        s.parse::<u32>()
            .map_err(|_| format!("`{s}` is not a count in `{expect}`"))
    };
    let mut extra = Stats::default();
    for i in (12..w.len()).step_by(2) {
        let slot = match w[i] {
            "lost" => &mut extra.lost,
            "late" => &mut extra.late_max,
            "nmpc_jobs" => &mut extra.nmpc_jobs,
            "nmpc_missed" => &mut extra.nmpc_missed,
            _ => continue,
        };
        *slot = match w[i + 1] {
            "-" if w[i] == "late" => None,
            _ => Some(n(i + 1)?),
        };
    }
    Ok(Stats {
        lost: extra.lost,
        late_max: extra.late_max,
        nmpc_jobs: extra.nmpc_jobs,
        nmpc_missed: extra.nmpc_missed,
        step_min: n(1)?,
        step_max: n(2)?,
        step_last: n(3)?,
        isr_min: n(5)?,
        isr_max: n(6)?,
        isr_last: n(7)?,
        samples: n(9)?,
        overruns: n(11)?,
    })
}

/// State of the recorder from `rec status` (`ok rec <state> <frames>`).
pub fn parse_rec_status(details: &str) -> Result<(String, usize), String> {
    let mut w = details.split_whitespace();
    match (w.next(), w.next(), w.next(), w.next()) {
        (Some("rec"), Some(state), Some(n), None)
            if matches!(state, "idle" | "armed" | "triggered" | "done") =>
        {
            n.parse::<usize>()
                .map(|n| (state.to_string(), n))
                .map_err(|_| format!("frame count `{n}` is not a number"))
        }
        _ => Err("expected `ok rec idle|armed|triggered|done <frames>`".into()),
    }
}

/// Channel names of the `rec sel` reply (`ok rec sel <name>...`).
pub fn parse_rec_sel(details: &str) -> Result<Vec<String>, String> {
    let mut w = details.split_whitespace();
    if (w.next(), w.next()) != (Some("rec"), Some("sel")) {
        return Err("expected `ok rec sel <signal>...`".into());
    }
    let names: Vec<String> = w.map(str::to_string).collect();
    if names.is_empty() {
        return Err("no channels in the reply".into());
    }
    Ok(names)
}

/// One frame line of `rec read`: `<index> <v0> <v1> ...` with `channels` values (any
/// number of at least one for `None`).
pub fn parse_frame(line: &str, channels: Option<usize>) -> Result<(usize, Vec<f64>), String> {
    let mut w = line.split_whitespace();
    let i = w
        .next()
        .and_then(|s| s.parse::<usize>().ok())
        .ok_or("no frame index")?;
    let v = w
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| format!("`{s}` is not a number"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    match channels {
        Some(n) if v.len() != n => Err(format!("{} values, expected {n}", v.len())),
        None if v.is_empty() => Err("no values".into()),
        _ => Ok((i, v)),
    }
}

/// A reply's details parsed by `parse`, or [`SerialError::BadReply`] naming the command.
fn typed<T>(
    command: &str,
    resp: &Response,
    parse: impl FnOnce(&str) -> Result<T, String>,
) -> Result<T, SerialError> {
    parse(&resp.details).map_err(|why| SerialError::BadReply {
        command: command.into(),
        line: resp.reply_line(),
        why,
    })
}

/// Requests with a typed answer.
impl Client {
    /// `get <param>`: the parameter's value.
    pub fn get(&mut self, param: &str) -> Result<f64, SerialError> {
        let r = self.send(&Command::Get(param))?;
        typed(&format!("get {param}"), &r, |_| parse_get(&r, param))
    }

    /// `stats`: the timing counts.
    pub fn stats(&mut self) -> Result<Stats, SerialError> {
        let r = self.send(&Command::Stats)?;
        typed("stats", &r, parse_stats)
    }

    /// `rec status`: the recorder's state and frame count.
    pub fn rec_status(&mut self) -> Result<(String, usize), SerialError> {
        let r = self.send(&Command::Rec(RecCmd::Status))?;
        typed("rec status", &r, parse_rec_status)
    }

    /// `rec div`: the recorder's divider (`ok rec div <n>`, n >= 1).
    pub fn rec_divider(&mut self) -> Result<u32, SerialError> {
        let r = self.send(&Command::Rec(RecCmd::Divider(None)))?;
        typed("rec div", &r, |d| {
            d.strip_prefix("rec div ")
                .and_then(|n| n.parse::<u32>().ok())
                .filter(|n| *n >= 1)
                .ok_or_else(|| "expected `ok rec div <n>`, n >= 1".into())
        })
    }

    /// `rec sel <names>`: the channel names the firmware selected.
    pub fn rec_select(&mut self, signals: &[Signal]) -> Result<Vec<String>, SerialError> {
        let line = select_line(signals)?;
        let r = self.raw(&line)?;
        typed(&line, &r, parse_rec_sel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::client::{parse_line, scripted::client};
    use proptest::prelude::*;

    #[test]
    fn typed_replies_parse_and_refuse_garbage() {
        let s = parse_stats("step 10 20 15 isr 30 40 35 samples 1000 overruns 2").unwrap();
        assert_eq!((s.step_max, s.isr_last, s.overruns), (20, 35, 2));
        assert!(parse_stats("step 10 20 isr 30 40 35 samples 1000 overruns 2").is_err());
        assert!(parse_stats("step a 20 15 isr 30 40 35 samples 1000 overruns 2").is_err());
        assert!(parse_stats("").is_err());
        assert_eq!((s.lost, s.late_max, s.nmpc_jobs), (None, None, None));
        let base = "step 10 20 15 isr 30 40 35 samples 1000 overruns 2";
        let s = parse_stats(&format!("{base} lost 3 late 77 nmpc_jobs 99 nmpc_missed 1")).unwrap();
        assert_eq!(
            (s.lost, s.late_max, s.nmpc_jobs, s.nmpc_missed),
            (Some(3), Some(77), Some(99), Some(1))
        );
        let s = parse_stats(&format!("{base} lost 0 late - future 5")).unwrap();
        assert_eq!((s.lost, s.late_max), (Some(0), None));
        assert!(parse_stats(&format!("{base} lost x")).is_err());
        assert!(parse_stats(&format!("{base} lost")).is_err());
        assert!(parse_stats(&format!("{base} nmpc_jobs -")).is_err());
        assert_eq!(
            parse_rec_status("rec done 1024").unwrap(),
            ("done".to_string(), 1024)
        );
        assert!(parse_rec_status("rec sleeping 3").is_err());
        assert!(parse_rec_status("rec done -1").is_err());
        assert_eq!(
            parse_rec_sel("rec sel ref_um y_um").unwrap(),
            vec!["ref_um".to_string(), "y_um".to_string()]
        );
        assert!(parse_rec_sel("rec sel").is_err());
        assert_eq!(
            parse_frame("3 1.5 -2 inf 4", Some(4)).unwrap(),
            (3, vec![1.5, -2.0, f64::INFINITY, 4.0])
        );
        assert!(parse_frame("3 1.5 -2 4", Some(4)).is_err());
        assert!(parse_frame("x 1 2 3 4", None).is_err());
        assert!(parse_frame("3 1 2 3 zz", Some(4)).is_err());
        let r = Response {
            data: vec![],
            details: "u_max 150".into(),
        };
        assert_eq!(parse_get(&r, "u_max"), Ok(150.0));
        assert!(parse_get(&r, "u_min").is_err());
    }

    proptest! {
        #[test]
        fn garbage_replies_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut c = client(&[], &bytes, true);
            for _ in 0..4 {
                let _ = c.raw("rec read 0 4");
            }
            if let Ok(s) = std::str::from_utf8(&bytes) {
                let _ = parse_stats(s);
                let _ = parse_rec_status(s);
                let _ = parse_frame(s, None);
                let _ = parse_line(s);
            }
        }
    }
}
