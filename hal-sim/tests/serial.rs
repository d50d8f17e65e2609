//! `piezo serial` against a fake firmware in this process: a TCP listener thread runs the
//! firmware's own board-independent executor (`piezo_core::firmware`: the same
//! `Ctl::execute`, recorder and `stream_frames`) behind the firmware's line buffer and
//! parser, with a first-order stage in place of the H743's on-chip converters. On the host
//! the executor builds with the f32 number type at 100 kHz.

/// The firmware as the H743 builds it with its on-chip converters.
mod control {
    pub use piezo_core::firmware::*;
    use piezo_core::firmware::{Converters, OnChip};
    pub type Ctl = piezo_core::firmware::Ctl<OnChip>;
    pub const DAC_MAX: i32 = OnChip::DAC_MAX;
}

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
use std::process::Command as Process;
use std::thread;
use std::time::Duration;

use hal_sim::cli::serial::record::{record, RecordArgs};
use hal_sim::cli::serial::wave::{TableArgs, WaveArgs, WaveCmd};
use hal_sim::cli::serial::{connect, execute, Action, Conn};
use hal_sim::serial::SerialError;
use piezo_core::command::{self, Command, LineBuffer, RecCmd};

/// Control periods run before each command is executed (the firmware runs on while the
/// host talks).
const PERIODS_PER_LINE: usize = 300;

/// The firmware's control state and a stage: y follows 0.16 um/V of the output with a lag.
struct Fake {
    ctl: control::Ctl,
    y_um: f64,
    dac: i32,
    /// ADC code at 0 um (0: the stage at rest reads the bottom code, out of range).
    code_at_zero: f64,
}

impl Fake {
    fn new() -> Self {
        let mut ctl = control::Ctl::new(control::c(control::SAMPLE_HZ as f64));
        // A noise-free stage: a resting one repeats its code, so the stuck-code detector off.
        ctl.lp.stuck_limit = 0;
        Self {
            ctl,
            y_um: 0.0,
            dac: 0,
            code_at_zero: 0.0,
        }
    }

    fn run(&mut self, periods: usize) {
        for _ in 0..periods {
            let volts = self.dac as f64 * 150.0 / control::DAC_MAX as f64;
            self.y_um += 0.3 * (0.16 * volts - self.y_um);
            let code = (self.code_at_zero + self.y_um * 655.35).clamp(0.0, 65535.0) as i32;
            [self.dac] = self.ctl.lp.step([code]);
            self.ctl.record([code], [self.dac]);
            self.ctl.timing.step.record(40);
            self.ctl.timing.isr.record(60);
        }
    }

    /// What the boards' command task does with one line.
    fn answer(&mut self, line: Result<&[u8], command::Error>, out: &mut VecDeque<u8>) {
        self.run(PERIODS_PER_LINE);
        self.ctl.serve(line, out);
    }
}

/// Serves one connection (TCP stream or serial port) until it closes: boot noise first,
/// then one reply per command line.
fn serve(s: &mut (impl Read + Write), fake: &mut Fake) {
    s.write_all(b"bench: table\n\xff\xfegarbage\nready\nhalf a li")
        .ok();
    let mut lb = LineBuffer::new();
    let mut buf = [0u8; 512];
    loop {
        let n = match s.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => n,
            // A serial port's read timeout: keep listening.
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(_) => return,
        };
        let mut out = VecDeque::new();
        for &b in &buf[..n] {
            if let Some(line) = lb.push(b) {
                fake.answer(line, &mut out);
            }
        }
        if s.write_all(out.make_contiguous()).is_err() {
            return;
        }
    }
}

/// Serves TCP connections one after another on one firmware state, like a UART that stays
/// up while host programs come and go.
fn spawn_firmware() -> String {
    spawn_firmware_with(Fake::new())
}

/// [`spawn_firmware`] on a given firmware and stage state.
fn spawn_firmware_with(mut fake: Fake) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    thread::spawn(move || {
        for mut s in listener.incoming().flatten() {
            serve(&mut s, &mut fake);
        }
    });
    addr
}

fn conn(addr: &str) -> Conn {
    Conn::tcp(addr, 5.0)
}

fn run(addr: &str, action: Action) -> anyhow::Result<String> {
    let mut c = connect(&conn(addr))?;
    let mut out = Vec::new();
    execute(&mut c, action, false, &mut out)?;
    Ok(String::from_utf8(out).unwrap())
}

/// Runs `action`, which must fail with an error that mentions `why`.
fn refused(addr: &str, action: Action, why: &str) {
    let e = run(addr, action).unwrap_err();
    assert!(e.to_string().contains(why), "{e}");
}

fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("serial-{name}"))
}

/// A free-running capture of `ref_um` into `tmp(out)`, every `every`-th period.
fn ref_capture(out: &str, every: u32) -> RecordArgs {
    RecordArgs {
        signals: vec!["ref_um".into()],
        trigger: "now".into(),
        pre: 0,
        wait_s: 10.0,
        wall_cap_s: 600.0,
        no_arm: false,
        frames: None,
        text: true,
        xy: false,
        every,
        out: tmp(out),
        svg: None,
    }
}

fn read_csv(path: &PathBuf) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn typed_commands_drive_the_firmware_executor() {
    let addr = spawn_firmware();
    let out = run(
        &addr,
        Action::Mode {
            law: "ff+pid".into(),
            ff: Some("ims-cbw".into()),
        },
    )
    .unwrap();
    assert_eq!(out, "ok ff ims-cbw\nok mode ff+pid\n");

    let out = run(
        &addr,
        Action::Limits {
            u_min: None,
            u_max: Some(140.0),
            slew: Some(20_000.0),
        },
    )
    .unwrap();
    assert_eq!(out, "output 0 V .. 140 V, slew limit 20000 V/s (20 V/ms)\n");

    let out = run(
        &addr,
        Action::Wave(WaveCmd::Sine(WaveArgs {
            amplitude: 5.0,
            freq: 200.0,
            offset: 10.0,
        })),
    )
    .unwrap();
    assert!(out.starts_with("ok wave sine 5"), "{out}");

    // A 2-axis scan on this 1-axis firmware: refused with err 13, the command named as
    // sent (the default centre made explicit).
    refused(
        &addr,
        Action::Wave(WaveCmd::Raster {
            x_span: 10.0,
            y_span: 6.0,
            lines: 4,
            line_freq: 20.0,
            center: None,
        }),
        "`wave raster 10 6 4 20 5 3`: firmware error 13",
    );
    refused(
        &addr,
        Action::Wave(WaveCmd::Lissajous {
            x_amp: 6.0,
            y_amp: 5.0,
            fx: 40.0,
            fy: 30.0,
            phase: 45.0,
            center: Some(vec![10.0]),
        }),
        "--center takes two positions x,y",
    );
    let out = run(&addr, Action::Axis { axis: None }).unwrap();
    assert_eq!(out, "ok axis 0 of 1\n");

    // The firmware refuses; the error names the command and the numbered error.
    let e = run(
        &addr,
        Action::Mode {
            law: "warp-drive".into(),
            ff: None,
        },
    )
    .unwrap_err();
    match e.downcast_ref::<SerialError>() {
        Some(SerialError::Firmware { command, code, .. }) => {
            assert_eq!((command.as_str(), *code), ("mode warp-drive", Some(9)))
        }
        other => panic!("{other:?}"),
    }
    assert!(
        e.to_string()
            .contains("`mode warp-drive`: firmware error 9: unknown mode name (UnknownMode)"),
        "{e}"
    );
    refused(
        &addr,
        Action::Limits {
            u_min: None,
            u_max: Some(200.0),
            slew: None,
        },
        "`set u_max 200`: firmware error 8",
    );

    let out = run(&addr, Action::Status).unwrap();
    for want in [
        "u_max           140",
        "sample_hz       100000",
        "control step    min 40",
        "recorder        idle",
    ] {
        assert!(out.contains(want), "{want:?} missing in\n{out}");
    }
}

/// `wave sine 5 16 10`: 5 um at 16 Hz around 10 um.
fn sine_5um_16hz(addr: &str) {
    run(
        addr,
        Action::Wave(WaveCmd::Sine(WaveArgs {
            amplitude: 5.0,
            freq: 16.0,
            offset: 10.0,
        })),
    )
    .unwrap();
}

#[test]
fn the_recorder_comes_back_as_csv_with_units() {
    let addr = spawn_firmware();
    sine_5um_16hz(&addr);
    let (csv, svg) = (tmp("rec.csv"), tmp("rec.svg"));
    let out = run(
        &addr,
        Action::Record(RecordArgs {
            signals: vec!["ref_um".into(), "y_um".into(), "u_volts".into()],
            trigger: "rise:ref_um:10".into(),
            pre: 64,
            out: csv.clone(),
            svg: Some(svg.clone()),
            ..ref_capture("unused.csv", 1)
        }),
    )
    .unwrap();
    assert!(out.contains("recorded 1024 frames at 100000 Hz"), "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.contains("# units: i [frame], t_s [s], ref_um [um], y_um [um], u_volts [V]"),
        "{text:.300}"
    );
    let (header, rows) = read_csv(&csv);
    // The fourth channel keeps the signal it had (the recorder has 4 channels).
    assert_eq!(
        header,
        ["i", "t_s", "ref_um", "y_um", "u_volts", "ff_volts"]
    );
    assert_eq!(rows.len(), 1024);
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r[0], k as f64);
        let t = (k as f64 - 64.0) / 100_000.0;
        assert!((r[1] - t).abs() < 1e-9, "row {k}: t_s {}", r[1]);
        assert!((4.99..=15.01).contains(&r[2]), "row {k}: ref_um {}", r[2]);
        assert!((0.0..=140.0).contains(&r[4]), "row {k}: u_volts {}", r[4]);
    }
    // Frame 64 is the trigger: the rising crossing of 10 um.
    assert!(
        rows[63][2] < 10.0 && rows[64][2] >= 10.0,
        "{:?}",
        &rows[62..66]
    );
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // The header is the record convention: `t_s`, `u_volts` and `y_um` are the time,
    // input and output `piezo fit` reads; the other signals are kept by name.
    let r = hal_sim::record::Record::read(&csv).unwrap();
    assert_eq!(r.unit_note, None);
    assert_eq!(r.t[64], 0.0);
    assert_eq!(r.u, vec![rows.iter().map(|r| r[4]).collect::<Vec<_>>()]);
    assert_eq!(r.y, vec![rows.iter().map(|r| r[3]).collect::<Vec<_>>()]);
    let extras: Vec<&str> = r.extra.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(extras, ["i", "ref_um", "ff_volts"]);

    // The same capture again without arming.
    let mut c = connect(&conn(&addr)).unwrap();
    let again = record(
        &mut c,
        &RecordArgs {
            signals: vec!["a".into()],
            trigger: "now".into(),
            pre: 64,
            wait_s: 1.0,
            wall_cap_s: 600.0,
            no_arm: true,
            frames: None,
            text: true,
            xy: false,
            every: 1,
            out: tmp("unused.csv"),
            svg: None,
        },
    )
    .unwrap();
    assert_eq!(again.channels, ["a", "ch1", "ch2", "ch3"]);
    assert_eq!(again.frames.len(), 1024);
    assert_eq!(again.frames[64][0], rows[64][2]);
}

#[test]
fn the_binary_sends_raw_lines_and_fails_loudly() {
    let addr = spawn_firmware();
    let piezo = env!("CARGO_BIN_EXE_piezo");
    let out = Process::new(piezo)
        .args([
            "serial",
            "--tcp",
            &addr,
            "--",
            "ping",
            "get u_max",
            "rec status",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout, "ok pong\nok u_max 150\nok rec idle 0\n");

    let out = Process::new(piezo)
        .args(["serial", "--tcp", &addr, "--keep-going", "--"])
        .args(["set u_max 1e9", "wave sine 1 2 3", "jump"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stdout.starts_with("err 8 value out of range\nok wave sine"),
        "{stdout}"
    );
    assert!(
        stdout.ends_with("err 3 unknown command (try help)\n"),
        "{stdout}"
    );
    assert!(stderr.contains("`jump`: firmware error 3"), "{stderr}");
    assert!(stderr.contains("2 of 3 commands failed"), "{stderr}");

    let out = Process::new(piezo)
        .args([
            "serial",
            "--tcp",
            &addr,
            "wave",
            "sine",
            "5 furlongs",
            "1Hz",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown unit `furlongs`"));
}

#[test]
fn silent_closing_and_babbling_peers_are_clear_errors() {
    // Accepts and never answers.
    let silent = TcpListener::bind("127.0.0.1:0").unwrap();
    let silent_addr = silent.local_addr().unwrap().to_string();
    thread::spawn(move || {
        let mut keep = Vec::new();
        for s in silent.incoming() {
            keep.push(s);
        }
    });
    let mut c = conn(&silent_addr);
    c.timeout_s = 0.2;
    let e = connect(&c).err().unwrap();
    assert!(
        format!("{e:#}").contains("`ping`: no reply within 0.2 s"),
        "{e:#}"
    );

    // Answers with noise, then hangs up.
    let babbler = TcpListener::bind("127.0.0.1:0").unwrap();
    let babbler_addr = babbler.local_addr().unwrap().to_string();
    thread::spawn(move || {
        for s in babbler.incoming() {
            let Ok(mut s) = s else { continue };
            let mut buf = [0u8; 64];
            let _ = s.read(&mut buf);
            s.write_all(b"\x00\x01ok\xffpong?\nerr\nerr zz top\n").ok();
            thread::sleep(Duration::from_millis(20));
        }
    });
    let e = connect(&conn(&babbler_addr)).err().unwrap();
    assert!(
        format!("{e:#}").contains("connection closed before the reply"),
        "{e:#}"
    );
    let mut c = conn(&babbler_addr);
    c.no_sync = true;
    let mut client = connect(&c).unwrap();
    let e = client.raw("stats").expect_err("garbage is not a reply");
    // The first `err` line ends the command, however malformed.
    assert!(matches!(e, SerialError::Firmware { code: None, .. }), "{e}");
    let _ = TcpStream::connect(&babbler_addr);
}

#[test]
fn a_trigger_that_never_fires_times_out_and_does_not_block_the_next_capture() {
    let addr = spawn_firmware();
    let args = |trigger: &str, wait_s: f64| RecordArgs {
        trigger: trigger.into(),
        wait_s,
        ..ref_capture("never.csv", 1)
    };
    refused(
        &addr,
        Action::Record(args("rise:ref_um:1000", 0.3)),
        "still armed after 0.3 s (trigger `rise:ref_um:1000` never fired?)",
    );
    let out = run(&addr, Action::Record(args("now", 10.0))).unwrap();
    assert!(out.contains("recorded 1024 frames"), "{out}");
}

/// `--port`: the binary opens the slave side of a pseudo-terminal, the fake firmware answers
/// on the master side (the same code path as a USB-serial adapter or the ST-LINK VCP).
#[test]
fn the_binary_speaks_over_a_serial_port() {
    use serialport::SerialPort;
    let (mut master, slave) = serialport::TTYPort::pair().expect("pseudo-terminal pair");
    let name = slave.name().expect("slave name");
    thread::spawn(move || {
        let mut fake = Fake::new();
        serve(&mut master, &mut fake);
    });
    let piezo = env!("CARGO_BIN_EXE_piezo");
    let out = Process::new(piezo)
        .args(["serial", "--port", &name, "--baud", "115200", "--"])
        .args(["ping", "get u_max", "mode open-loop"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    // Numbers as the executor's number type prints them (150, 150.00000 in Q16.16).
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert_eq!(lines[0], "ok pong");
    assert_eq!(
        lines[1].strip_prefix("ok u_max ").map(|v| v.parse::<f64>()),
        Some(Ok(150.0)),
        "{stdout}"
    );
    assert_eq!(lines[2], "ok mode open-loop");
    let out = Process::new(piezo)
        .args(["serial", "--port", &name, "wave", "hold", "12.5um"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        stdout
            .trim()
            .strip_prefix("ok wave hold ")
            .map(|v| v.parse::<f64>()),
        Some(Ok(12.5)),
        "{stdout}"
    );
    drop(slave);
}

#[test]
fn a_table_from_a_file_is_loaded_in_lines_and_the_reference_follows_it() {
    let addr = spawn_firmware();
    // 20 points: three `table add` lines.
    let pts: Vec<f64> = (0..20)
        .map(|k| 20.0 + 15.0 * ((k * 7 % 20) as f64 / 19.0))
        .collect();
    let file = tmp("points.csv");
    let text: Vec<String> = pts.iter().map(|v| format!("{v}")).collect();
    std::fs::write(&file, format!("# um\n{}\n", text.join(",\n"))).unwrap();
    let table = |file: Option<PathBuf>, points: Vec<f64>| {
        Action::Wave(WaveCmd::Table(TableArgs {
            freq: 200.0,
            points,
            file,
        }))
    };
    let out = run(&addr, table(Some(file), vec![])).unwrap();
    assert_eq!(out, "ok table 20\nok wave table 200 20\n");
    let mut c = connect(&conn(&addr)).unwrap();
    let rec = record(&mut c, &ref_capture("table.csv", 1)).unwrap();
    drop(c);
    // Two periods of 500 samples: every point is passed (within one sample's travel).
    let r: Vec<f64> = rec.frames.iter().map(|f| f[0]).collect();
    let travel = r
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    assert!(travel > 0.0 && travel < 1.0, "{travel}");
    for p in &pts {
        let near = r
            .iter()
            .map(|y| (y - p).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(near <= travel, "{p} um: nearest {near} um");
    }

    // Too many points: refused before anything is sent (the table keeps its 20).
    refused(&addr, table(None, vec![1.0; 65]), "65 points");
    let out = run(
        &addr,
        Action::Send {
            lines: vec!["table len".into()],
        },
    )
    .unwrap();
    assert_eq!(out, "ok table 20\n");

    let out = run(
        &addr,
        Action::Wave(WaveCmd::Steps {
            low: 10.0,
            high: 30.0,
            levels: 5,
            freq: 2.0,
        }),
    )
    .unwrap();
    assert_eq!(out, "ok wave steps 10 30 5 2\n");
}

#[test]
fn a_divided_capture_spans_longer() {
    let addr = spawn_firmware();
    run(
        &addr,
        Action::Send {
            lines: vec!["wave triangle 10 100 20".into()],
        },
    )
    .unwrap();
    let mut c = connect(&conn(&addr)).unwrap();
    let rec = record(&mut c, &ref_capture("every.csv", 5)).unwrap();
    // Every 5th period: 20 kHz of frames; the 4000 um/s triangle moves 0.2 um per frame.
    assert_eq!(rec.sample_hz, 20_000.0);
    assert!((rec.t_s(1) - rec.t_s(0) - 5e-5).abs() < 1e-12);
    let mut d: Vec<f64> = rec
        .frames
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    assert!((median - 0.2).abs() < 1e-3, "{median}");
    // Out of range: refused by the firmware.
    let e = c.send(&Command::Rec(RecCmd::Divider(Some(0)))).unwrap_err();
    assert!(e.to_string().contains("firmware error 8"), "{e}");
}

/// `piezo serial record` then `piezo fit` on its CSV, as at the bench: the fake stage is
/// 0.16 um/V with a lag far shorter than a frame, so the fit must find that gain.
#[test]
fn a_recorded_capture_is_fitted_by_piezo_fit() {
    // The sensor reads mid-range at rest (at its bottom code the firmware latches a
    // sensor-range fault that holds the output at 0 V).
    let addr = spawn_firmware_with(Fake {
        code_at_zero: 32768.0,
        ..Fake::new()
    });
    run(
        &addr,
        Action::Mode {
            law: "open-loop".into(),
            ff: None,
        },
    )
    .unwrap();
    sine_5um_16hz(&addr);
    let csv = tmp("fit-rec.csv");
    run(
        &addr,
        Action::Record(RecordArgs {
            signals: vec!["ref_um".into(), "y_um".into(), "u_volts".into()],
            out: csv.clone(),
            ..ref_capture("unused.csv", 20)
        }),
    )
    .unwrap();
    let fault = run(
        &addr,
        Action::Send {
            lines: vec!["fault".into()],
        },
    )
    .unwrap();
    assert!(fault.starts_with("ok fault none"), "{fault}");
    let out = Process::new(env!("CARGO_BIN_EXE_piezo"))
        .args([
            "fit",
            "--model",
            "pi",
            "--json",
            "--quiet",
            "--generations",
            "20",
        ])
        .arg("--train")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Units stated in the header: no note about assumed ones.
    assert!(!String::from_utf8_lossy(&out.stderr).contains("note"));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let m = &j["train_metrics"][0]["metrics"];
    assert_eq!(m["samples"].as_u64(), Some(1024));
    assert_eq!(j["sample_rate_hz"].as_f64(), Some(5000.0));
    // A real excitation (tens of volts, about 12 um), and the fit explains y_um from
    // u_volts (the linear stage: a few per cent at most; the reference or a constant
    // column in their place would not fit).
    let rec = hal_sim::record::Record::read(&csv).unwrap();
    let span = |v: &[f64]| {
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - v.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    assert!(span(&rec.u[0]) > 10.0 && span(&rec.y[0]) > 1.0);
    assert!(m["re_pct"].as_f64().unwrap() < 2.0, "{m}");
}

/// A report in the shape `piezo fit --model cbw --out <dir>` writes (`fit.json`).
fn fit_json(name: &str, model: &str, params: &[(&str, f64)]) -> PathBuf {
    let params: Vec<serde_json::Value> = params
        .iter()
        .map(|(k, v)| serde_json::json!([k, v]))
        .collect();
    let report = serde_json::json!({
        "model": model, "train": "rec.csv", "valid": null, "linear_step": null,
        "parts": [{"kind": "siso", "input": 0, "output": 0, "fit": {
            "model": model, "params": params, "sign": 1.0, "offset": -0.5,
            "upsample": 1, "linear": []}}],
        "train_metrics": [], "valid_metrics": [], "valid_from_rest_metrics": [], "seconds": 0.1
    });
    let path = tmp(name);
    std::fs::write(&path, serde_json::to_string_pretty(&report).unwrap()).unwrap();
    path
}

/// The value `piezo serial params` prints for `name`.
fn param(listing: &str, name: &str) -> f64 {
    listing
        .lines()
        .find_map(|l| {
            let mut w = l.split_whitespace();
            (w.next() == Some(name)).then(|| w.next().unwrap().parse().unwrap())
        })
        .unwrap_or_else(|| panic!("no {name} in {listing}"))
}

#[test]
fn load_fit_sends_the_identified_cbw_and_params_reads_it_back() {
    let addr = spawn_firmware();
    let before = run(&addr, params()).unwrap();
    assert_eq!(param(&before, "cbw_d"), 0.16, "{before}");
    assert_eq!(param(&before, "u_max"), 150.0);
    assert_eq!(param(&before, "pid_ki"), 2000.0);
    // Units from the core's settings table.
    for row in [
        ["u_max", "150", "V"],
        ["slew", "20000", "V/s"],
        ["pid_ki", "2000", "V/(um"],
    ] {
        assert!(
            before.lines().any(|l| l.split_whitespace().take(3).eq(row)),
            "{row:?} in {before}"
        );
    }

    // gamma/beta 0.4 of beta 0.005: gamma 0.002.
    let good = fit_json(
        "fit-good.json",
        "cbw",
        &[
            ("d", 0.21),
            ("alpha", 0.06),
            ("beta", 0.005),
            ("gamma/beta", 0.4),
        ],
    );
    let out = run(&addr, Action::LoadFit { fit: good.clone() }).unwrap();
    assert!(out.contains("ok cbw 0.21 0.06 0.005 0.002"), "{out}");
    assert!(out.contains("offset -0.5 um is not sent"), "{out}");
    let after = run(&addr, params()).unwrap();
    for (k, v) in [
        ("cbw_d", 0.21),
        ("cbw_alpha", 0.06),
        ("cbw_beta", 0.005),
        ("cbw_gamma", 0.002),
    ] {
        assert!((param(&after, k) - v).abs() < 1e-6, "{k}: {after}");
    }
    assert_eq!(param(&after, "pid_ki"), 2000.0);

    // The firmware refuses a model IMS cannot invert (d = 0.05 below the largest
    // hysteresis slope 0.093 um/V): the error names the file and the firmware's reply, and
    // the model stays.
    let refused = fit_json(
        "fit-refused.json",
        "cbw",
        &[
            ("d", 0.05),
            ("alpha", 0.07),
            ("beta", 0.02),
            ("gamma/beta", 0.5),
        ],
    );
    let e = run(
        &addr,
        Action::LoadFit {
            fit: refused.clone(),
        },
    )
    .unwrap_err();
    let msg = format!("{e:#}");
    assert!(msg.contains(&refused.display().to_string()), "{msg}");
    assert!(msg.contains("refused the CBW model of parts[0]"), "{msg}");
    assert!(msg.contains("error 8"), "{msg}");
    let still = run(&addr, params()).unwrap();
    assert!((param(&still, "cbw_d") - 0.21).abs() < 1e-6, "{still}");

    // A report in nm is converted to the firmware's um (d and alpha / 1000), never sent
    // 1000 times too large; one in an unknown unit is refused and nothing is sent.
    let with_units = |name: &str, d: f64, alpha: f64, unit: &str| {
        let path = fit_json(
            name,
            "cbw",
            &[
                ("d", d),
                ("alpha", alpha),
                ("beta", 0.005),
                ("gamma/beta", 0.4),
            ],
        );
        let mut j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        j["input_unit"] = "V".into();
        j["output_unit"] = unit.into();
        std::fs::write(&path, j.to_string()).unwrap();
        path
    };
    let nm = with_units("fit-nm.json", 230.0, 65.0, "nm");
    let out = run(&addr, Action::LoadFit { fit: nm }).unwrap();
    assert!(out.contains("ok cbw 0.23 0.065 0.005 0.002"), "{out}");
    assert!(
        out.contains("in nm and V was converted to um and V"),
        "{out}"
    );
    assert!(out.contains("offset -0.0005 um is not sent"), "{out}");
    let ft = with_units("fit-ft.json", 0.25, 0.06, "ft");
    let msg = format!("{:#}", run(&addr, Action::LoadFit { fit: ft }).unwrap_err());
    assert!(msg.contains("unknown length unit `ft`"), "{msg}");
    let still = run(&addr, params()).unwrap();
    assert!((param(&still, "cbw_d") - 0.23).abs() < 1e-6, "{still}");

    // Reports without a CBW fit or with a key missing: named, nothing sent.
    let pi = fit_json("fit-pi.json", "pi", &[("c2", 0.1)]);
    let msg = format!("{:#}", run(&addr, Action::LoadFit { fit: pi }).unwrap_err());
    assert!(
        msg.contains("fit-pi.json: no CBW fit in `parts` (found: pi (siso))"),
        "{msg}"
    );
    let partial = fit_json("fit-partial.json", "cbw", &[("d", 0.21), ("alpha", 0.06)]);
    let msg = format!(
        "{:#}",
        run(&addr, Action::LoadFit { fit: partial }).unwrap_err()
    );
    assert!(
        msg.contains("fit-partial.json: parts[0].fit.params lacks `beta`"),
        "{msg}"
    );
    let missing = tmp("fit-missing.json");
    let msg = format!(
        "{:#}",
        run(&addr, Action::LoadFit { fit: missing }).unwrap_err()
    );
    assert!(
        msg.contains("cannot read") && msg.contains("fit-missing.json"),
        "{msg}"
    );
}

fn set(addr: &str, name: &str, v: f32) {
    let mut c = connect(&conn(addr)).unwrap();
    c.send(&piezo_core::command::Command::Set(name, v)).unwrap();
}

fn params() -> Action {
    Action::Params {
        save: None,
        restore: None,
    }
}

#[test]
fn params_save_and_restore_round_trip_and_a_bad_file_sends_nothing() {
    let addr = spawn_firmware();
    let file = tmp("params-saved.csv");
    let listing = run(
        &addr,
        Action::Params {
            save: Some(file.clone()),
            restore: None,
        },
    )
    .unwrap();
    let settable = piezo_core::firmware::SETTINGS
        .iter()
        .filter(|s| s.access != piezo_core::firmware::Access::ReadOnly)
        .count();
    assert!(
        listing.contains(&format!("saved {settable} settings")),
        "{listing}"
    );
    let saved = std::fs::read_to_string(&file).unwrap();
    assert!(saved.contains("\nlambda1,2000,1/s\n"), "{saved}");

    // Change some, then restore the file: every value is back.
    for (k, v) in [("lambda1", 1500.0), ("pid_kp", 0.25), ("u_max", 120.0)] {
        set(&addr, k, v);
    }
    let changed = run(&addr, params()).unwrap();
    assert_eq!(param(&changed, "lambda1"), 1500.0);
    let restored = run(
        &addr,
        Action::Params {
            save: None,
            restore: Some(file.clone()),
        },
    )
    .unwrap();
    assert!(
        restored.contains(&format!("restored {settable} settings")),
        "{restored}"
    );
    for (k, v) in [("lambda1", 2000.0), ("pid_kp", 0.5), ("u_max", 150.0)] {
        assert_eq!(param(&restored, k), v, "{k}: {restored}");
    }

    // A file with one bad line (a gain in the wrong unit) sends nothing.
    set(&addr, "lambda1", 1500.0);
    let bad = tmp("params-bad.csv");
    std::fs::write(&bad, saved.replace("pid_kp,0.5,V/um", "pid_kp,500,V/mm")).unwrap();
    let msg = format!(
        "{:#}",
        run(
            &addr,
            Action::Params {
                save: None,
                restore: Some(bad),
            },
        )
        .unwrap_err()
    );
    assert!(msg.contains("pid_kp in V/mm"), "{msg}");
    assert_eq!(param(&run(&addr, params()).unwrap(), "lambda1"), 1500.0);
}
