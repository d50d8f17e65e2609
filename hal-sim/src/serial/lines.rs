//! Command lines: built from the core's [`Command`] enum, checked with the core's parser.
use piezo_core::command::{
    self, Command, Points, RecCmd, TriggerCmd, MAX_LINE, MAX_WORDS, TABLE_ADD_MAX, TABLE_LEN,
};
use piezo_core::recorder::Signal;

use super::error::SerialError;

/// Writes `cmd` as the line the firmware's parser reads back as `cmd`. Numbers use the
/// shortest representation that round-trips (`f32` `Display`).
pub fn format_command(cmd: &Command<'_>) -> String {
    match cmd {
        Command::Empty => String::new(),
        Command::Ping => "ping".into(),
        Command::Help => "help".into(),
        Command::Get(name) => format!("get {name}"),
        Command::Set(name, v) => format!("set {name} {v}"),
        Command::Cbw([d, a, b, g]) => format!("cbw {d} {a} {b} {g}"),
        Command::Mode(law) => format!("mode {law}"),
        Command::Feedforward(name) => format!("ff {name}"),
        Command::WaveOff => "wave off".into(),
        Command::WaveHold(y_um) => format!("wave hold {y_um}"),
        Command::Wave {
            shape,
            amp_um,
            freq_hz,
            offset_um,
        } => format!("wave {} {amp_um} {freq_hz} {offset_um}", shape.name()),
        Command::WaveSteps {
            low_um,
            high_um,
            levels,
            freq_hz,
        } => format!("wave steps {low_um} {high_um} {levels} {freq_hz}"),
        Command::WaveTable(freq_hz) => format!("wave table {freq_hz}"),
        Command::WavePrbs {
            low_um,
            high_um,
            order,
            bit_hz,
            seed,
        } => format!("wave prbs {low_um} {high_um} {order} {bit_hz} {seed}"),
        Command::WaveChirp {
            amp_um,
            f0_hz,
            f1_hz,
            duration_s,
            offset_um,
        } => format!("wave chirp {amp_um} {f0_hz} {f1_hz} {duration_s} {offset_um}"),
        Command::WaveMultisine {
            amp_um,
            f0_hz,
            harmonics,
            offset_um,
            seed,
        } => format!("wave multisine {amp_um} {f0_hz} {harmonics} {offset_um} {seed}"),
        Command::WaveRaster {
            span_um: [sx, sy],
            lines,
            line_hz,
            center_um: [cx, cy],
        } => format!("wave raster {sx} {sy} {lines} {line_hz} {cx} {cy}"),
        Command::WaveLissajous {
            amp_um: [ax, ay],
            freq_hz: [fx, fy],
            phase_deg,
            center_um: [cx, cy],
        } => format!("wave lissajous {ax} {ay} {fx} {fy} {phase_deg} {cx} {cy}"),
        Command::Axis(None) => "axis".into(),
        Command::Axis(Some(n)) => format!("axis {n}"),
        Command::TableClear => "table clear".into(),
        Command::TableLen => "table len".into(),
        Command::TableAdd(points) => {
            let mut s = String::from("table add");
            for v in points.as_slice() {
                s.push_str(&format!(" {v}"));
            }
            s
        }
        Command::Stats => "stats".into(),
        Command::StatsReset => "stats reset".into(),
        Command::Rec(r) => match r {
            RecCmd::Select(names) => {
                let mut s = String::from("rec sel");
                for n in names.iter() {
                    s.push(' ');
                    s.push_str(n);
                }
                s
            }
            RecCmd::Trigger(t) => match t {
                TriggerCmd::Now => "rec trig now".into(),
                TriggerCmd::Rising {
                    channel,
                    level,
                    pre,
                } => format!("rec trig rise {channel} {level} {pre}"),
                TriggerCmd::Falling {
                    channel,
                    level,
                    pre,
                } => format!("rec trig fall {channel} {level} {pre}"),
                TriggerCmd::Level {
                    channel,
                    level,
                    pre,
                } => format!("rec trig level {channel} {level} {pre}"),
            },
            RecCmd::Arm => "rec arm".into(),
            RecCmd::Stop => "rec stop".into(),
            RecCmd::Status => "rec status".into(),
            RecCmd::Read { start, count } => format!("rec read {start} {count}"),
            RecCmd::Divider(None) => "rec div".into(),
            RecCmd::Divider(Some(n)) => format!("rec div {n}"),
            RecCmd::Length(None) => "rec len".into(),
            RecCmd::Length(Some(n)) => format!("rec len {n}"),
            RecCmd::Bin { start, count } => format!("rec bin {start} {count}"),
        },
        Command::Fault => "fault".into(),
        Command::FaultClear => "fault clear".into(),
        Command::Bench => "bench".into(),
        Command::Selftest => "selftest".into(),
        Command::Save => "save".into(),
        Command::Load => "load".into(),
        Command::Defaults => "defaults".into(),
    }
}

/// [`format_command`], then the firmware's parser must read the line back as `cmd` and it
/// must fit the firmware's line buffer.
pub fn checked_line(cmd: &Command<'_>) -> Result<String, SerialError> {
    let line = format_command(cmd);
    check_built(&line, Some(cmd))?;
    Ok(line)
}

/// Checks a line the host built: it fits [`MAX_LINE`] and the firmware's parser accepts it
/// (and, with `expect`, reads it back as that command).
fn check_built(line: &str, expect: Option<&Command<'_>>) -> Result<(), SerialError> {
    let bad = |why: String| SerialError::BadCommand {
        command: line.to_string(),
        why,
    };
    if line.len() > MAX_LINE {
        return Err(bad(format!(
            "{} bytes, the firmware takes at most {MAX_LINE} (it would answer err 1)",
            line.len()
        )));
    }
    match command::parse(line.as_bytes()) {
        Err(e) => Err(bad(format!("the protocol parser rejects it: {e}"))),
        Ok(parsed) => match expect {
            Some(cmd) if parsed != *cmd => Err(bad(format!(
                "the protocol parser reads it as {parsed:?}, not {cmd:?}"
            ))),
            _ => Ok(()),
        },
    }
}

/// `rec sel <names>`: every name must be a recorder [`Signal`].
pub fn select_line(signals: &[Signal]) -> Result<String, SerialError> {
    let mut line = String::from("rec sel");
    for s in signals {
        line.push(' ');
        line.push_str(s.name());
    }
    if signals.is_empty() || signals.len() > MAX_WORDS - 2 {
        return Err(SerialError::BadCommand {
            command: line,
            why: format!("select 1 to {} signals", MAX_WORDS - 2),
        });
    }
    check_built(&line, None)?;
    Ok(line)
}

/// The `table add` lines that load `points_um` (after a `table clear`): as many points
/// per line as fit [`MAX_LINE`] and [`TABLE_ADD_MAX`], each line checked by the firmware's
/// parser. Refuses fewer than 2 or more than [`TABLE_LEN`] points before anything is sent.
pub fn table_lines(points_um: &[f32]) -> Result<Vec<String>, SerialError> {
    if !(2..=TABLE_LEN).contains(&points_um.len()) {
        return Err(SerialError::BadCommand {
            command: "wave table".into(),
            why: format!(
                "{} points; the firmware's table takes 2 to {TABLE_LEN}",
                points_um.len()
            ),
        });
    }
    let mut lines = Vec::new();
    let mut chunk: Vec<f32> = Vec::new();
    let line_of = |chunk: &[f32]| -> Result<String, SerialError> {
        let pts = Points::from_slice(chunk).ok_or_else(|| SerialError::BadCommand {
            command: "table add".into(),
            why: format!("1 to {TABLE_ADD_MAX} points per line"),
        })?;
        checked_line(&Command::TableAdd(pts))
    };
    for &v in points_um {
        chunk.push(v);
        let fits = chunk.len() <= TABLE_ADD_MAX
            && format_command(&Command::TableAdd(
                Points::from_slice(&chunk).expect("1..=TABLE_ADD_MAX points"),
            ))
            .len()
                <= MAX_LINE;
        if !fits {
            chunk.pop();
            lines.push(line_of(&chunk)?);
            chunk.clear();
            chunk.push(v);
        }
    }
    lines.push(line_of(&chunk)?);
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;
    use piezo_core::command::{Shape, MAX_LEVELS, MAX_LINES};
    use proptest::prelude::*;

    #[test]
    fn built_lines_are_checked_by_the_firmware_parser() {
        assert_eq!(
            checked_line(&Command::Wave {
                shape: Shape::Sine,
                amp_um: 5.0,
                freq_hz: 100.0,
                offset_um: 10.0
            })
            .unwrap(),
            "wave sine 5 100 10"
        );
        // A negative amplitude is refused on the host with the protocol's own error.
        let e = checked_line(&Command::Wave {
            shape: Shape::Sine,
            amp_um: -5.0,
            freq_hz: 100.0,
            offset_um: 10.0,
        })
        .unwrap_err();
        assert!(e.to_string().contains("err 8"), "{e}");
        // Too long for the firmware's line buffer.
        let e = checked_line(&Command::Wave {
            shape: Shape::Triangle,
            amp_um: 3.0e38,
            freq_hz: 3.0e38,
            offset_um: -3.0e38,
        })
        .unwrap_err();
        assert!(e.to_string().contains("at most 96"), "{e}");
        assert_eq!(
            select_line(&[Signal::RefUm, Signal::UVolts]).unwrap(),
            "rec sel ref_um u_volts"
        );
        assert!(select_line(&[]).is_err());
    }

    #[test]
    fn table_lines_refuse_bad_counts_and_pack_lines() {
        assert!(table_lines(&[1.0]).is_err());
        assert!(table_lines(&[0.0; TABLE_LEN + 1]).is_err());
        let lines = table_lines(&[1.0; 20]).unwrap();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0], "table add 1 1 1 1 1 1 1 1");
        assert_eq!(lines[2], "table add 1 1 1 1");
        // Long numbers: the line length limits a line before the word count does.
        let long = [-1.2345678e-12f32; 8];
        let lines = table_lines(&long).unwrap();
        assert!(lines.len() > 1, "{lines:?}");
        assert!(lines.iter().all(|l| l.len() <= MAX_LINE));
    }

    fn finite() -> impl Strategy<Value = f32> {
        prop_oneof![
            -1.0e6f32..1.0e6,
            any::<f32>().prop_filter("finite", |v| v.is_finite() && v.abs() < 1e12),
            Just(0.0f32),
            Just(-0.0f32),
        ]
    }

    fn name() -> impl Strategy<Value = String> {
        "[a-z_+\\-0-9]{1,16}"
    }

    proptest! {
        /// Every command the host can build reads back identically with the firmware's
        /// parser (or the host refuses it before sending).
        #[test]
        fn every_built_command_round_trips(
            which in 0usize..35, a in finite(), b in finite(), d in finite(),
            n in name(), i in 0usize..5000, k in 0usize..5000,
        ) {
            let shape = [Shape::Sine, Shape::Triangle, Shape::Square][which % 3];
            let cmd = match which {
                0 => Command::Ping,
                1 => Command::Help,
                2 => Command::Get(&n),
                3 => Command::Set(&n, a),
                4 => Command::Mode(&n),
                5 => Command::Feedforward(&n),
                6 => Command::WaveOff,
                7 => Command::WaveHold(a),
                8..=10 => Command::Wave { shape, amp_um: a.abs(), freq_hz: b.abs(), offset_um: d },
                11 => Command::Stats,
                12 => Command::StatsReset,
                13 => Command::Rec(RecCmd::Trigger(TriggerCmd::Now)),
                14 => Command::Rec(RecCmd::Trigger(TriggerCmd::Rising { channel: i, level: a, pre: k })),
                15 => Command::Rec(RecCmd::Trigger(TriggerCmd::Falling { channel: i, level: a, pre: k })),
                16 => Command::Rec(RecCmd::Trigger(TriggerCmd::Level { channel: i, level: a, pre: k })),
                17 => Command::Rec([
                    RecCmd::Read { start: i, count: k },
                    RecCmd::Bin { start: i, count: k },
                    RecCmd::Length(Some(k)),
                    RecCmd::Length(None),
                ][i % 4]),
                18 => Command::Rec([RecCmd::Arm, RecCmd::Stop, RecCmd::Status][i % 3]),
                19 => Command::WaveSteps {
                    low_um: a,
                    high_um: d,
                    levels: 2 + (i % (MAX_LEVELS as usize - 1)) as u16,
                    freq_hz: b.abs(),
                },
                20 => Command::WaveTable(b.abs()),
                21 => Command::TableClear,
                22 => Command::TableLen,
                23 => Command::TableAdd(Points::from_slice(&[a, b, d][..1 + i % 3]).unwrap()),
                24 => Command::WaveRaster {
                    span_um: [a.abs(), b.abs()],
                    lines: 1 + (i % MAX_LINES as usize) as u16,
                    line_hz: d.abs(),
                    center_um: [d, a],
                },
                25 => Command::WaveLissajous {
                    amp_um: [a.abs(), d.abs()],
                    freq_hz: [b.abs(), a.abs()],
                    phase_deg: (d % 360.0),
                    center_um: [b, d],
                },
                26 => Command::Axis(Some(i)),
                27 => Command::Axis(None),
                28 => Command::Rec(RecCmd::Divider([None, Some(k)][i % 2])),
                29 => Command::Cbw([a, b, d, -a]),
                30 => Command::Selftest,
                32 => Command::WavePrbs {
                    low_um: a,
                    high_um: d,
                    order: 2 + (i % 19) as u8,
                    bit_hz: b.abs().max(1e-3),
                    seed: k as u32,
                },
                33 => Command::WaveChirp {
                    amp_um: a.abs(),
                    f0_hz: b.abs(),
                    f1_hz: d.abs(),
                    duration_s: a.abs().max(1e-3),
                    offset_um: d,
                },
                34 => Command::WaveMultisine {
                    amp_um: a.abs(),
                    f0_hz: b.abs().max(1e-3),
                    harmonics: 1 + (i % 32) as u8,
                    offset_um: d,
                    seed: k as u32,
                },
                _ => Command::Bench,
            };
            let line = format_command(&cmd);
            match checked_line(&cmd) {
                Ok(l) => {
                    prop_assert_eq!(&l, &line);
                    prop_assert_eq!(command::parse(l.as_bytes()), Ok(cmd));
                }
                // Only an overlong line may be refused.
                Err(e) => prop_assert!(line.len() > MAX_LINE, "{e}"),
            }
        }

        /// The table is loaded in lines the firmware reads back as exactly these points.
        #[test]
        fn table_lines_carry_every_point(points in proptest::collection::vec(finite(), 2..=TABLE_LEN)) {
            let lines = table_lines(&points).unwrap();
            let mut back = Vec::new();
            for l in &lines {
                prop_assert!(l.len() <= MAX_LINE);
                match command::parse(l.as_bytes()) {
                    Ok(Command::TableAdd(p)) => back.extend_from_slice(p.as_slice()),
                    other => prop_assert!(false, "{l}: {other:?}"),
                }
            }
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(&back), bits(&points));
            // Greedy: the next line's first point would not have fitted in this one.
            for w in lines.windows(2) {
                let next = w[1].split(' ').nth(2).unwrap();
                let full = w[0].split(' ').count() - 2 == TABLE_ADD_MAX;
                prop_assert!(full || w[0].len() + 1 + next.len() > MAX_LINE, "{:?}", w);
            }
        }

        #[test]
        fn select_lines_round_trip(idx in proptest::collection::vec(0usize..Signal::COUNT, 1..5)) {
            let sig: Vec<Signal> = idx.iter().map(|&i| Signal::ALL[i]).collect();
            let line = select_line(&sig).unwrap();
            match command::parse(line.as_bytes()) {
                Ok(Command::Rec(RecCmd::Select(w))) => {
                    let names: Vec<&str> = w.iter().collect();
                    let want: Vec<&str> = sig.iter().map(|s| s.name()).collect();
                    prop_assert_eq!(names, want);
                    prop_assert_eq!(format_command(&Command::Rec(RecCmd::Select(w))), line);
                }
                other => prop_assert!(false, "{other:?}"),
            }
        }
    }
}
