//! `defmt-log ELF LOG [--period N]`: decodes a defmt log (the bytes a QEMU run wrote
//! over semihosting) with the ELF's table and prints one line per frame. Then checks the
//! firmware's timing lines (`step cycles min .. max .. last .. | isr min .. max .. last ..
//! | samples .. overruns ..`): at least one; in each, min <= last <= max for the step and
//! the interrupt, the step within the interrupt, no overrun, the maximum below the period
//! (`--period`, in the line's units: cycles or ticks); samples increasing. Exit 1 on a
//! failed check, with the reason.
use anyhow::{bail, Context, Result};
use defmt_decoder::{DecodeError, Table};

/// The numbers of one timing line.
#[derive(Debug, PartialEq)]
struct Timing {
    step: [u64; 3],
    isr: [u64; 3],
    samples: u64,
    overruns: u64,
}

/// `step cycles min A max B last C | isr min D max E last F | samples N overruns O`.
fn parse_timing(line: &str) -> Option<Timing> {
    let rest = line.split("step cycles ").nth(1)?;
    let nums: Vec<u64> = rest
        .split(|c: char| !c.is_ascii_digit())
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().ok())
        .collect::<Option<_>>()?;
    match nums[..] {
        [a, b, c, d, e, f, n, o] => Some(Timing {
            step: [a, b, c],
            isr: [d, e, f],
            samples: n,
            overruns: o,
        }),
        _ => None,
    }
}

/// Why a timing line is not sane, if it is not.
fn insane(t: &Timing, period: Option<u64>, prev_samples: u64) -> Option<String> {
    let ordered = |[min, max, last]: [u64; 3]| min <= last && last <= max;
    if !ordered(t.step) || !ordered(t.isr) {
        return Some("min <= last <= max does not hold".into());
    }
    if t.step[1] > t.isr[1] || t.step[1] == 0 {
        return Some("the step's maximum is 0 or above the interrupt's".into());
    }
    if t.overruns != 0 {
        return Some(format!("{} overruns", t.overruns));
    }
    if let Some(p) = period {
        if t.isr[1] >= p {
            return Some(format!("interrupt maximum {} >= period {p}", t.isr[1]));
        }
    }
    if t.samples <= prev_samples {
        return Some(format!("samples {} not above {prev_samples}", t.samples));
    }
    None
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (elf, log) = match &args[..] {
        [e, l, ..] => (e, l),
        _ => bail!("usage: defmt-log ELF LOG [--period N]"),
    };
    let period = match args.iter().position(|a| a == "--period") {
        Some(i) => Some(
            args.get(i + 1)
                .context("--period needs a number")?
                .parse::<u64>()
                .context("--period needs a whole number")?,
        ),
        None => None,
    };
    let bytes = std::fs::read(elf).with_context(|| format!("reading {elf}"))?;
    let table = Table::parse(&bytes)
        .with_context(|| format!("{elf}: no defmt table"))?
        .context("the ELF has no .defmt section")?;
    let data = std::fs::read(log).with_context(|| format!("reading {log}"))?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(&data);
    let (mut frames, mut timing, mut prev) = (0, 0, 0u64);
    loop {
        match decoder.decode() {
            Ok(frame) => {
                frames += 1;
                let level = frame
                    .level()
                    .map_or("print".into(), |l| l.as_str().to_uppercase());
                let msg = frame.display_message().to_string();
                println!("{level:5} {msg}");
                if let Some(t) = parse_timing(&msg) {
                    if let Some(why) = insane(&t, period, prev) {
                        bail!("timing line not sane ({why}): {msg}");
                    }
                    prev = t.samples;
                    timing += 1;
                }
            }
            Err(DecodeError::UnexpectedEof) => break,
            Err(DecodeError::Malformed) => bail!("malformed defmt frame after {frames} frames"),
        }
    }
    if timing == 0 {
        bail!("{frames} frames decoded, no timing line");
    }
    println!("defmt-log: {frames} frames decoded, {timing} timing lines sane");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timing_lines_parse_and_insane_ones_are_named() {
        let t = parse_timing(
            "step cycles min 4 max 33 last 11 | isr min 29 max 60 last 41 | samples 10000 overruns 0",
        )
        .unwrap();
        assert_eq!(t.step, [4, 33, 11]);
        assert_eq!(insane(&t, Some(250), 0), None);
        assert!(insane(&t, Some(50), 0).is_some());
        assert!(insane(&t, None, 10000).is_some());
        let bad = Timing { overruns: 1, ..t };
        assert!(insane(&bad, None, 0).unwrap().contains("overruns"));
        assert!(parse_timing("reset cause: pin").is_none());
    }
}
