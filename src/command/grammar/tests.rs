//! The grammar's unit tests: every command, its limits and its errors.
use super::*;
use crate::command::LineBuffer;
use proptest::prelude::*;

fn p(s: &str) -> Result<Command<'_>, Error> {
    parse(s.as_bytes())
}

#[test]
fn parses_every_command() {
    assert_eq!(p("ping"), Ok(Command::Ping));
    assert_eq!(p("selftest"), Ok(Command::Selftest));
    assert_eq!(p("save"), Ok(Command::Save));
    assert_eq!(p("load"), Ok(Command::Load));
    assert_eq!(p("defaults"), Ok(Command::Defaults));
    assert_eq!(p("save now"), Err(Error::TooManyArguments));
    assert!(p("selftest now").is_err());
    assert_eq!(p("  ping \r"), Ok(Command::Ping));
    assert_eq!(p(""), Ok(Command::Empty));
    assert_eq!(p("get kp"), Ok(Command::Get("kp")));
    assert_eq!(p("set kp 1.5e-3"), Ok(Command::Set("kp", 1.5e-3)));
    assert_eq!(
        p("cbw 0.39 0.27 1e-3 1.8e-4"),
        Ok(Command::Cbw([0.39, 0.27, 1e-3, 1.8e-4]))
    );
    assert_eq!(p("cbw 0.39 0.27 1e-3"), Err(Error::MissingArgument));
    assert_eq!(p("cbw 0.39 0.27 1e-3 1 2"), Err(Error::TooManyArguments));
    assert_eq!(p("mode hgo"), Ok(Command::Mode("hgo")));
    assert_eq!(p("ff ims-cbw"), Ok(Command::Feedforward("ims-cbw")));
    assert_eq!(p("wave off"), Ok(Command::WaveOff));
    assert_eq!(p("wave hold 12.5"), Ok(Command::WaveHold(12.5)));
    assert_eq!(
        p("wave sine 5 100 20"),
        Ok(Command::Wave {
            shape: Shape::Sine,
            amp_um: 5.0,
            freq_hz: 100.0,
            offset_um: 20.0
        })
    );
    assert_eq!(p("stats"), Ok(Command::Stats));
    assert_eq!(p("stats reset"), Ok(Command::StatsReset));
    assert_eq!(p("fault"), Ok(Command::Fault));
    assert_eq!(p("fault clear"), Ok(Command::FaultClear));
    assert_eq!(p("fault reset"), Err(Error::BadKeyword));
    assert_eq!(p("fault clear now"), Err(Error::TooManyArguments));
    assert_eq!(p("rec arm"), Ok(Command::Rec(RecCmd::Arm)));
    assert_eq!(
        p("rec trig rise 1 2.5 100"),
        Ok(Command::Rec(RecCmd::Trigger(TriggerCmd::Rising {
            channel: 1,
            level: 2.5,
            pre: 100
        })))
    );
    assert_eq!(
        p("rec read 0 16"),
        Ok(Command::Rec(RecCmd::Read {
            start: 0,
            count: 16
        }))
    );
    match p("rec sel y_um u_volts") {
        Ok(Command::Rec(RecCmd::Select(w))) => {
            assert_eq!(w.len(), 2);
            assert_eq!(w.get(0), Some("y_um"));
            assert_eq!(w.get(1), Some("u_volts"));
            assert_eq!(w.get(2), None);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn parses_scans_and_axis() {
    assert_eq!(
        p("wave raster 20 10 16 50"),
        Ok(Command::WaveRaster {
            span_um: [20.0, 10.0],
            lines: 16,
            line_hz: 50.0,
            center_um: [10.0, 5.0],
        })
    );
    assert_eq!(
        p("wave raster 20 10 16 50 30 40"),
        Ok(Command::WaveRaster {
            span_um: [20.0, 10.0],
            lines: 16,
            line_hz: 50.0,
            center_um: [30.0, 40.0],
        })
    );
    let liss = |phase_deg, center_um| {
        Ok(Command::WaveLissajous {
            amp_um: [5.0, 4.0],
            freq_hz: [30.0, 40.0],
            phase_deg,
            center_um,
        })
    };
    assert_eq!(p("wave lissajous 5 4 30 40"), liss(90.0, [5.0, 4.0]));
    assert_eq!(p("wave lissajous 5 4 30 40 45"), liss(45.0, [5.0, 4.0]));
    assert_eq!(
        p("wave lissajous 5 4 30 40 10 20"),
        liss(90.0, [10.0, 20.0])
    );
    assert_eq!(
        p("wave lissajous 5 4 30 40 -45 10 20"),
        liss(-45.0, [10.0, 20.0])
    );
    for (line, e) in [
        ("wave raster 20 10 16", Error::MissingArgument),
        ("wave raster 20 10 16 50 30", Error::MissingArgument),
        ("wave raster 20 10 16 50 30 40 1", Error::TooManyArguments),
        ("wave raster 20 10 0 50", Error::OutOfRange),
        ("wave raster 20 10 4097 50", Error::OutOfRange),
        ("wave raster -20 10 16 50", Error::OutOfRange),
        ("wave raster 20 10 16 -50", Error::OutOfRange),
        ("wave raster 20 10 1.5 50", Error::BadNumber),
        ("wave lissajous 5 4 30", Error::MissingArgument),
        ("wave lissajous 5 4 30 -40", Error::OutOfRange),
        ("wave lissajous 5 -4 30 40", Error::OutOfRange),
        ("wave lissajous 5 4 30 40 400", Error::OutOfRange),
        ("wave lissajous 5 4 30 40 nan", Error::BadNumber),
        ("wave lissajous 5 4 30 40 90 1 2 3", Error::TooManyArguments),
        ("axis -1", Error::BadNumber),
        ("axis 1 2", Error::TooManyArguments),
    ] {
        assert_eq!(p(line), Err(e), "{line}");
    }
    assert_eq!(p("axis"), Ok(Command::Axis(None)));
    assert_eq!(p("rec div"), Ok(Command::Rec(RecCmd::Divider(None))));
    assert_eq!(p("rec div 10"), Ok(Command::Rec(RecCmd::Divider(Some(10)))));
    assert_eq!(p("rec div 1 2"), Err(Error::TooManyArguments));
    assert_eq!(p("axis 1"), Ok(Command::Axis(Some(1))));
}

#[test]
fn every_error_has_its_code() {
    assert_eq!(p("jump").unwrap_err().code(), 3);
    assert_eq!(p("set kp").unwrap_err(), Error::MissingArgument);
    assert_eq!(p("set kp nan").unwrap_err(), Error::BadNumber);
    assert_eq!(p("set kp inf").unwrap_err(), Error::BadNumber);
    assert_eq!(p("set kp 1 2").unwrap_err(), Error::TooManyArguments);
    assert_eq!(p("wave saw 1 2").unwrap_err(), Error::BadKeyword);
    assert_eq!(p("wave sine 1 -2").unwrap_err(), Error::OutOfRange);
    assert_eq!(p("rec read -1 3").unwrap_err(), Error::BadNumber);
    assert_eq!(parse(b"ping\x00").unwrap_err(), Error::NotAscii);
    assert_eq!(
        parse(&[b'a'; MAX_LINE + 1]).unwrap_err(),
        Error::LineTooLong
    );
    assert_eq!(
        p("a b c d e f g h i j k").unwrap_err(),
        Error::TooManyArguments
    );
    assert_eq!(
        Error::UnknownParam.to_string(),
        "err 7 unknown parameter".to_string()
    );
}

#[test]
fn parses_excitations() {
    assert_eq!(
        p("wave prbs 10 30 12 1000"),
        Ok(Command::WavePrbs {
            low_um: 10.0,
            high_um: 30.0,
            order: 12,
            bit_hz: 1000.0,
            seed: 1
        })
    );
    assert_eq!(p("wave prbs 10 30 12 1000 9").map(|_| ()), Ok(()));
    assert_eq!(p("wave prbs 10 30 21 1000"), Err(Error::OutOfRange));
    assert_eq!(p("wave prbs 10 30 1 1000"), Err(Error::OutOfRange));
    assert_eq!(p("wave prbs 10 30 8 0"), Err(Error::OutOfRange));
    assert_eq!(p("wave prbs 10 30 8"), Err(Error::MissingArgument));
    assert_eq!(
        p("wave chirp 5 1 200 10 50"),
        Ok(Command::WaveChirp {
            amp_um: 5.0,
            f0_hz: 1.0,
            f1_hz: 200.0,
            duration_s: 10.0,
            offset_um: 50.0
        })
    );
    assert_eq!(p("wave chirp 5 1 200 0"), Err(Error::OutOfRange));
    assert_eq!(p("wave chirp 5 1 200 1 2 3"), Err(Error::TooManyArguments));
    assert_eq!(
        p("wave multisine 5 2 32 50 7"),
        Ok(Command::WaveMultisine {
            amp_um: 5.0,
            f0_hz: 2.0,
            harmonics: 32,
            offset_um: 50.0,
            seed: 7
        })
    );
    assert_eq!(p("wave multisine 5 2 33"), Err(Error::OutOfRange));
    assert_eq!(p("wave multisine 5 0 3"), Err(Error::OutOfRange));
}

#[test]
fn parses_steps_and_table_commands() {
    assert_eq!(
        p("wave steps 10 30 5 2.5"),
        Ok(Command::WaveSteps {
            low_um: 10.0,
            high_um: 30.0,
            levels: 5,
            freq_hz: 2.5
        })
    );
    assert_eq!(p("wave steps 1 2 64 1").map(|_| ()), Ok(()));
    assert_eq!(p("wave steps 1 2 1 1"), Err(Error::OutOfRange));
    assert_eq!(p("wave steps 1 2 65 1"), Err(Error::OutOfRange));
    assert_eq!(p("wave steps 1 2 4 -1"), Err(Error::OutOfRange));
    assert_eq!(p("wave steps 1 2 4.5 1"), Err(Error::BadNumber));
    assert_eq!(p("wave steps 1 2 4"), Err(Error::MissingArgument));
    assert_eq!(p("wave steps 1 2 4 1 0"), Err(Error::TooManyArguments));
    assert_eq!(p("wave table 10"), Ok(Command::WaveTable(10.0)));
    assert_eq!(p("wave table"), Err(Error::MissingArgument));
    assert_eq!(p("wave table -1"), Err(Error::OutOfRange));
    assert_eq!(p("wave table 1 2"), Err(Error::TooManyArguments));
    assert_eq!(p("table clear"), Ok(Command::TableClear));
    assert_eq!(p("table len"), Ok(Command::TableLen));
    assert_eq!(p("table"), Err(Error::MissingArgument));
    assert_eq!(p("table drop"), Err(Error::BadKeyword));
    assert_eq!(p("table len 3"), Err(Error::TooManyArguments));
    assert_eq!(p("table add"), Err(Error::MissingArgument));
    assert_eq!(p("table add 1 x"), Err(Error::BadNumber));
    assert_eq!(
        p("table add 1.5 -2 3e1"),
        Ok(Command::TableAdd(
            Points::from_slice(&[1.5, -2.0, 30.0]).unwrap()
        ))
    );
    let full = "table add 1 2 3 4 5 6 7 8";
    match p(full) {
        Ok(Command::TableAdd(pts)) => {
            assert_eq!(pts.len(), TABLE_ADD_MAX);
            assert_eq!(pts.as_slice(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        p("table add 1 2 3 4 5 6 7 8 9"),
        Err(Error::TooManyArguments)
    );
    assert!(Points::from_slice(&[]).is_none());
    assert!(Points::from_slice(&[0.0; TABLE_ADD_MAX + 1]).is_none());
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = parse(&bytes);
        let mut lb = LineBuffer::new();
        for &b in &bytes {
            if let Some(Ok(line)) = lb.push(b) {
                let _ = parse(line);
            }
        }
    }

    #[test]
    fn arbitrary_words_never_panic(words in proptest::collection::vec(
        prop_oneof![
            proptest::sample::select(&[
                "rec", "trig", "sel", "wave", "sine", "set", "1e3", "-1", "read", "3",
                "rise", "stats", "reset", "hold", "now", "arm", "steps", "table",
                "add", "clear", "len", "raster", "lissajous", "axis",
            ][..]).prop_map(|s| s.to_string()),
            "[a-z0-9.]{0,6}",
        ],
        0..12)) {
        let line = words.join(" ");
        let _ = parse(line.as_bytes());
    }
}
