//! `piezo serial identify` against the firmware's own executor in this process: a link
//! whose far end is `piezo_core::firmware::Ctl` (the executor, recorder and `stream_bin` of
//! the boards) driving a stage whose CBW differs from the firmware's built-in model (more
//! gain, a wider loop) behind the on-chip converters' scaling. Every command line lets the
//! loop run a few hundred control periods first, as a firmware does while the host talks.
//! identify must load a model close to the stage's and cut the feedforward-only tracking
//! error several times; a voltage range outside the firmware's limits is refused before
//! anything moves.
use std::collections::VecDeque;
use std::io;
use std::time::Duration;

use hal_sim::cli::serial::identify::{self, IdentifyArgs};
use hal_sim::serial::{Client, Link};
use piezo_core::command::{self, Command, LineBuffer, RecCmd};
use piezo_core::firmware::{c, Converters, Ctl, OnChip, SAMPLE_HZ};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};

/// Control periods run before each command line is answered.
const PERIODS_PER_LINE: usize = 300;

/// The stage: CBW (000 eq. 1-2) with `d`, `alpha`, `beta`, `gamma`, then a 500 Hz lag.
struct Stage {
    model: Cbw<f64>,
    state: BwState<f64>,
    y_um: f64,
}

impl Stage {
    fn new(p: [f64; 4]) -> Self {
        let model = Cbw::with_n1(p[0], p[1], p[2], p[3]).unwrap();
        Self {
            model,
            state: model.init(0.0),
            y_um: 0.0,
        }
    }

    fn step(&mut self, volts: f64) -> f64 {
        let dt = 1.0 / SAMPLE_HZ as f64;
        let y = self.model.step(&mut self.state, volts, dt);
        self.y_um += (1.0 - (-2.0 * std::f64::consts::PI * 500.0 * dt).exp()) * (y - self.y_um);
        self.y_um
    }
}

struct Fake {
    ctl: Ctl<OnChip>,
    stage: Stage,
    dac: i32,
    lb: LineBuffer,
    out: VecDeque<u8>,
    /// The ADC's noise, +-2 LSB from an LCG: a real converter never repeats one code for
    /// long, and the firmware's stuck-code check trips on a reading that does.
    noise: u32,
}

impl Fake {
    fn new(stage: [f64; 4]) -> Self {
        Self {
            ctl: Ctl::<OnChip>::new(c(SAMPLE_HZ as f64)),
            stage: Stage::new(stage),
            dac: 0,
            lb: LineBuffer::new(),
            out: VecDeque::new(),
            noise: 1,
        }
    }

    /// The control period: stage, ADC code (the on-chip scaling: -10..110 um over 16
    /// bits), pipeline, DAC code (12 bits over 0..150 V), recorder.
    fn run(&mut self, periods: usize) {
        for _ in 0..periods {
            let volts = self.dac as f64 * 150.0 / OnChip::DAC_MAX as f64;
            let y = self.stage.step(volts);
            self.noise = self
                .noise
                .wrapping_mul(1_664_525)
                .wrapping_add(1_013_904_223);
            let lsb = (self.noise >> 29) as f64 - 3.5; // -3.5..3.5 in 8 steps
            let code = (y * 546.125 + 5461.25 + 0.6 * lsb)
                .round()
                .clamp(0.0, 65535.0) as i32;
            [self.dac] = self.ctl.lp.step([code]);
            self.ctl.record([code], [self.dac]);
            self.ctl.timing.step.record(40);
            self.ctl.timing.isr.record(60);
        }
    }

    fn answer(&mut self, line: Result<&[u8], command::Error>) {
        self.run(PERIODS_PER_LINE);
        self.ctl.serve(line, &mut self.out);
    }
}

impl Link for Fake {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        for &b in bytes {
            if let Some(line) = self.lb.push(b) {
                let line: Result<Vec<u8>, command::Error> = line.map(<[u8]>::to_vec);
                self.answer(line.as_deref().map_err(|e| *e));
            }
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        if self.out.is_empty() {
            std::thread::sleep(timeout.min(Duration::from_millis(1)));
            return Err(io::ErrorKind::TimedOut.into());
        }
        let n = buf.len().min(self.out.len());
        for b in buf.iter_mut().take(n) {
            *b = self.out.pop_front().unwrap();
        }
        Ok(n)
    }
}

fn args(out: &str) -> IdentifyArgs {
    use clap::Parser;
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        a: IdentifyArgs,
    }
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(out);
    Cli::parse_from([
        "identify",
        "--out",
        dir.to_str().unwrap(),
        "--no-diagnose",
        "--generations",
        "100",
    ])
    .a
}

/// The firmware's model before identify, and the stage (25 % more gain, a loop 1.6 times
/// wider on top: what `40-identify.sh` gives the QEMU stage, without the creep).
const BUILT_IN: [f64; 4] = [0.16, 0.07, 0.02, 0.01];
const STAGE: [f64; 4] = [0.2, 0.14, 0.02, 0.01];

#[test]
fn identify_loads_the_stages_model_and_cuts_the_tracking_error() {
    let mut c = Client::new(Box::new(Fake::new(STAGE)), Duration::from_secs(5));
    c.sync().unwrap();
    let a = args("identify-fake");
    let mut out = Vec::new();
    let r = identify::run(&mut c, &a, &mut out).unwrap();
    let text = String::from_utf8(out).unwrap();
    println!("{text}");
    assert_eq!(r.cbw_before, BUILT_IN);
    let line = format!(
        "identify: rmse before {:.4} um, after {:.4} um",
        r.rmse_before_um, r.rmse_after_um
    );
    assert!(text.contains(&line), "{text}");
    assert!(
        r.rmse_before_um > 3.0 * r.rmse_after_um,
        "before {} um, after {} um",
        r.rmse_before_um,
        r.rmse_after_um
    );
    // The loaded model is the stage's: d and alpha within a few percent (the fit sees the
    // 500 Hz lag through its linear part; the firmware's model is f32).
    for (k, (got, want)) in r.cbw.iter().zip(STAGE).enumerate().take(2) {
        assert!(
            (got / want - 1.0).abs() < 0.05,
            "parameter {k}: {got} vs {want}"
        );
    }
    assert_eq!(
        c.send(&Command::Get("cbw_d")).unwrap().details,
        format!("cbw_d {}", r.cbw[0] as f32)
    );
    for f in [
        "fit.json",
        "prbs.csv",
        "sines.csv",
        "held_back.csv",
        "before.csv",
        "after.csv",
        "identify.svg",
    ] {
        assert!(a.out.join(f).is_file(), "{f} not written");
    }
    // The firmware is left running the identified model in feedforward, no fault.
    assert!(c
        .send(&Command::Fault)
        .unwrap()
        .details
        .starts_with("fault none"));
}

#[test]
fn a_voltage_range_beyond_the_limits_is_refused_before_anything_moves() {
    let mut c = Client::new(Box::new(Fake::new(STAGE)), Duration::from_secs(5));
    c.sync().unwrap();
    c.send(&Command::Set("u_max", 120.0)).unwrap();
    let a = args("identify-refused");
    let e = identify::run(&mut c, &a, &mut Vec::new()).unwrap_err();
    assert!(e.to_string().contains("u_max 120 V"), "{e}");
    let r = c.send(&Command::Get("cbw_d")).unwrap();
    assert_eq!(r.details, "cbw_d 0.16");
    assert_eq!(
        c.send(&Command::Rec(RecCmd::Status)).unwrap().details,
        "rec idle 0"
    );
}

#[test]
fn a_model_the_firmware_refuses_leaves_its_model_in_place_and_says_so() {
    // d below the largest hysteresis slope (37-load-fit's refused model as a stage): the
    // fit finds it, the IMS cannot invert it, the firmware refuses it.
    let mut c = Client::new(
        Box::new(Fake::new([0.05, 0.07, 0.02, 0.01])),
        Duration::from_secs(5),
    );
    c.sync().unwrap();
    let len = |c: &mut Client| c.send(&Command::Rec(RecCmd::Length(None))).unwrap().details;
    let len_before = len(&mut c);
    let a = args("identify-refusal");
    let e = identify::run(&mut c, &a, &mut Vec::new()).unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("the firmware keeps its previous model")
            && msg.contains("[0.16, 0.07, 0.02, 0.01]")
            && msg.contains("refused the CBW model"),
        "{msg}"
    );
    assert_eq!(
        c.send(&Command::Get("cbw_d")).unwrap().details,
        "cbw_d 0.16"
    );
    assert!(a.out.join("fit.json").is_file());
    // Nothing left running: the capture length as before, no capture armed, the
    // reference held.
    assert_eq!(len(&mut c), len_before);
    let status = c.send(&Command::Rec(RecCmd::Status)).unwrap().details;
    assert!(!status.starts_with("rec armed"), "{status}");
    assert!(c
        .send(&Command::Fault)
        .unwrap()
        .details
        .starts_with("fault none"));
}
