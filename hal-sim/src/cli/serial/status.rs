//! `piezo serial status` and `stats`: link, parameters, timing and recorder state.
use std::io::Write;
use std::time::Instant;

use anyhow::Result;
use piezo_core::command::Command;

use crate::serial::replies::Stats;
use crate::serial::Client;

use super::params::print_params;

/// The timing counts, with microseconds when the counts' clock is known.
pub fn print_stats(out: &mut impl Write, s: &Stats, clock_hz: Option<f64>) -> Result<()> {
    let us = |n: u32| match clock_hz {
        Some(f) if f > 0.0 => format!(" ({:.3} us)", n as f64 / f * 1e6),
        _ => String::new(),
    };
    if s.samples == 0 {
        // Right after `stats reset` (or boot) min is the firmware's "none yet", u32::MAX.
        writeln!(out, "control step    no sample since the reset")?;
        writeln!(out, "interrupt       no sample since the reset")?;
        writeln!(out, "samples 0  overruns {}", s.overruns)?;
        return Ok(());
    }
    writeln!(
        out,
        "control step    min {}{} max {}{} last {}{}",
        s.step_min,
        us(s.step_min),
        s.step_max,
        us(s.step_max),
        s.step_last,
        us(s.step_last)
    )?;
    writeln!(
        out,
        "interrupt       min {}{} max {}{} last {}{}",
        s.isr_min,
        us(s.isr_min),
        s.isr_max,
        us(s.isr_max),
        s.isr_last,
        us(s.isr_last)
    )?;
    writeln!(out, "samples {}  overruns {}", s.samples, s.overruns)?;
    if let Some(lost) = s.lost {
        write!(out, "lost samples    {lost}")?;
        match s.late_max {
            Some(l) => writeln!(out, "  latest start after trigger {l}{}", us(l))?,
            None => writeln!(out)?,
        }
    }
    if let (Some(jobs), Some(missed)) = (s.nmpc_jobs, s.nmpc_missed) {
        writeln!(
            out,
            "nmpc solver     {jobs} jobs, {missed} missed (since the mode)"
        )?;
    }
    Ok(())
}

/// Link, parameters, timing and recorder state.
pub fn status(c: &mut Client, out: &mut impl Write) -> Result<()> {
    let t = Instant::now();
    c.send(&Command::Ping)?;
    writeln!(
        out,
        "link            ok ({:.1} ms round trip)",
        t.elapsed().as_secs_f64() * 1e3
    )?;
    print_params(c, out)?;
    print_stats(out, &c.stats()?, None)?;
    let (state, n) = c.rec_status()?;
    writeln!(out, "recorder        {state}, {n} frames")?;
    Ok(())
}

/// `stats [--clock] [--reset]`.
pub fn stats(
    c: &mut Client,
    reset: bool,
    clock_hz: Option<f64>,
    out: &mut impl Write,
) -> Result<()> {
    print_stats(out, &c.stats()?, clock_hz)?;
    if reset {
        c.send(&Command::StatsReset)?;
        writeln!(out, "counters reset")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::replies::parse_stats;

    fn printed(reply: &str) -> String {
        let mut out = Vec::new();
        print_stats(&mut out, &parse_stats(reply).unwrap(), Some(25e6)).unwrap();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn stats_print_the_deadlines_and_no_min_before_a_sample() {
        let p = printed(
            "step 5 54 12 isr 36 86 44 samples 160676 overruns 0 lost 0 late 166 \
             nmpc_jobs 2141 nmpc_missed 0",
        );
        assert!(p.contains("samples 160676  overruns 0\n"), "{p}");
        assert!(
            p.contains("lost samples    0  latest start after trigger 166 (6.640 us)\n"),
            "{p}"
        );
        assert!(p.contains("nmpc solver     2141 jobs, 0 missed"), "{p}");
        let p =
            printed("step 4294967295 0 0 isr 4294967295 0 0 samples 0 overruns 0 lost 0 late -");
        assert!(
            !p.contains("4294967295") && p.contains("no sample since the reset"),
            "{p}"
        );
        // An older firmware's reply: the lines it has.
        let p = printed("step 5 54 12 isr 36 86 44 samples 10 overruns 1");
        assert!(p.ends_with("samples 10  overruns 1\n"), "{p}");
    }
}
