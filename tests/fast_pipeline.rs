//! The fused step of the firmware's main mode (`src/pipeline/fused.rs`) against the generic
//! step (`Pipeline::step_generic`, the reference): two copies of the firmware's pipeline
//! (configured by the firmware module of the library) get the same ADC codes and the same
//! commands; one steps with `Pipeline::step` (fused where it applies), the other with
//! `step_generic`. The fused step does the same arithmetic in the same order, so the DAC
//! codes, the whole pipeline state (trace, counters, fault) and the laws' and compensators'
//! states must be equal, bit for bit, after every operation: random ADC codes (garbage and
//! out of the sensor window included), mode, law and compensator switches, faults, DAC
//! write failures, waves whose derivatives overflow the input guard's bound or `f32`.

use piezo_core::firmware::{self as control, c, Converters, SpiPair, FFS, LAWS, SAMPLE_HZ};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use piezo_core::pipeline::Wave;
use proptest::prelude::*;
use proptest::strategy::ValueTree;

/// The QEMU board's control state, over the SPI converter pair.
type Ctl = control::Ctl<SpiPair>;

/// Bits of the SPI converter pair.
const BITS: u32 = SpiPair::ADC_BITS;
const DAC_MAX: i32 = SpiPair::DAC_FULL;

/// The simulated stage of the firmware's QEMU board, in f64: CBW set 1, 500 Hz lag, the
/// 20-bit SPI converters.
struct Stage {
    m: Cbw<f64>,
    s: BwState<f64>,
    x: f64,
}

impl Stage {
    fn new() -> Self {
        let m = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
        Self {
            s: m.init(0.0),
            m,
            x: 0.0,
        }
    }
    /// ADC code of the position after a sample at the voltage of `dac` (20-bit codes).
    fn step(&mut self, dac: i32) -> i32 {
        let dt = 1.0 / SAMPLE_HZ as f64;
        let u = dac as f64 * 150.0 / DAC_MAX as f64;
        let v = self.m.step(&mut self.s, u, dt);
        let ad = (-control::STAGE_POLE_PER_S * dt).exp();
        self.x = ad * self.x + (1.0 - ad) * v;
        let half = (1i64 << (BITS - 1)) as f64;
        let code = (self.x - control::SPI_CENTER_UM) / (control::SPI_SPAN_UM / (2.0 * half));
        code.round().clamp(-half, half - 1.0) as i32
    }
}

/// The firmware's main mode (ff+hgo-robust on ims-cbw, the firmware's gains) on the QEMU
/// board's 20-bit converters.
fn main_mode() -> Ctl {
    let mut ctl = Ctl::new(c(SAMPLE_HZ as f64));
    ctl.lp.set_ff("ims-cbw").unwrap();
    ctl.lp.set_law("ff+hgo-robust").unwrap();
    ctl.lp
        .p
        .set_wave(0, Wave::sine(c(10.0), c(5.0), c(100.0)))
        .unwrap();
    ctl
}

/// Both copies are in the same state: DAC codes, trace, counters, fault, the laws' and the
/// compensators' states. Compared through `Debug`, which prints every `f32` so that it
/// reads back to the same bits (and a NaN, which `==` never equals, as `NaN`).
fn assert_same(fast: &Ctl, reference: &Ctl, what: &str) {
    let (a, b) = (&fast.lp.p, &reference.lp.p);
    assert_eq!(a.codes(), b.codes(), "{what}: DAC codes");
    let same = |x: String, y: String, part: &str| assert!(x == y, "{what}: {part}\n{x}\n{y}");
    same(
        format!("{:?}", a.state()),
        format!("{:?}", b.state()),
        "state",
    );
    same(
        format!("{:?}", a.feedback()),
        format!("{:?}", b.feedback()),
        "feedback",
    );
    same(
        format!("{:?}", a.feedforward()),
        format!("{:?}", b.feedforward()),
        "feedforward",
    );
}

#[derive(Debug, Clone)]
enum Op {
    /// Samples of the closed loop on the stage, with this much ADC noise (codes).
    Run {
        samples: u16,
        noise: i32,
    },
    /// One sample with this ADC code (any i32: garbage and out-of-window codes included).
    Code(i32),
    Law(usize),
    Ff(usize),
    ClearFault,
    DacFailed(i32),
    Sine {
        amp_um: f32,
        freq_hz: f32,
    },
    /// New output limits in place (V, V, V/s), the safe voltage clamped into them.
    Limits {
        lo: f32,
        hi: f32,
        slew: f32,
    },
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => (1u16..400, 0i32..200).prop_map(|(samples, noise)| Op::Run { samples, noise }),
        2 => any::<i32>().prop_map(Op::Code),
        1 => (0usize..LAWS.len() + 1).prop_map(Op::Law),
        1 => (0usize..FFS.len()).prop_map(Op::Ff),
        2 => Just(Op::ClearFault),
        1 => (-10i32..1 << 21).prop_map(Op::DacFailed),
        1 => (prop_oneof![0.0f32..40.0, Just(1e30f32), Just(3e38f32)], 0.0f32..2_000.0)
            .prop_map(|(amp_um, freq_hz)| Op::Sine { amp_um, freq_hz }),
        1 => (0.0f32..100.0, 1.0f32..150.0, prop_oneof![100.0f32..1e5, Just(1e9f32)])
            .prop_map(|(lo, w, slew)| Op::Limits { lo, hi: (lo + w).min(150.0), slew }),
    ]
}

/// Applies `op` to both copies; returns the samples run on the fused configuration.
fn apply(
    op: &Op,
    fast: &mut Ctl,
    reference: &mut Ctl,
    stage: &mut Stage,
    rng: &mut u64,
    dac: &mut i32,
) -> usize {
    let mut fused = 0;
    let mut sample = |code: i32, fast: &mut Ctl, reference: &mut Ctl| {
        if fast.lp.p.is_fused() && fast.lp.p.state().fault.is_none() {
            fused += 1;
        }
        let [a] = fast.lp.p.step([code]);
        let [b] = reference.lp.p.step_generic([code]);
        assert_eq!(a, b, "DAC code of ADC code {code}");
        let (lo, hi) = fast.lp.p.output(0).unwrap().code_range();
        assert!(a >= lo && a <= hi, "DAC code {a} outside {lo}..={hi}");
        a
    };
    match *op {
        Op::Run { samples, noise } => {
            for _ in 0..samples {
                // xorshift: reproducible noise without another dependency.
                *rng ^= *rng << 13;
                *rng ^= *rng >> 7;
                *rng ^= *rng << 17;
                let n = if noise > 0 {
                    (*rng % (2 * noise as u64 + 1)) as i32 - noise
                } else {
                    0
                };
                let code = stage.step(*dac).saturating_add(n);
                *dac = sample(code, fast, reference);
            }
        }
        Op::Code(code) => *dac = sample(code, fast, reference),
        Op::Law(i) => {
            let name = LAWS.get(i).copied().unwrap_or("feedforward");
            let a = fast.lp.set_law(name);
            let b = reference.lp.set_law(name);
            assert_eq!(a, b);
        }
        Op::Ff(i) => {
            fast.lp.set_ff(FFS[i]).unwrap();
            reference.lp.set_ff(FFS[i]).unwrap();
        }
        Op::ClearFault => {
            fast.lp.p.clear_fault();
            reference.lp.p.clear_fault();
        }
        Op::DacFailed(code) => {
            fast.lp.p.dac_write_failed(0, code);
            reference.lp.p.dac_write_failed(0, code);
        }
        Op::Sine { amp_um, freq_hz } => {
            let w = Wave::sine(c(10.0), amp_um, freq_hz);
            let a = fast.lp.p.set_wave(0, w);
            let b = reference.lp.p.set_wave(0, w);
            assert_eq!(a, b);
        }
        Op::Limits { lo, hi, slew } => {
            let l = piezo_core::pipeline::OutputLimits {
                volts_min: lo,
                volts_max: hi,
                slew_volts_per_s: slew,
            };
            let safe = c(control::SAFE_VOLTS).clamp(lo, hi);
            let a = fast.lp.p.set_limits(0, l, safe);
            let b = reference.lp.p.set_limits(0, l, safe);
            assert_eq!(a, b);
        }
    }
    fused
}

/// Two seconds of the main mode on the stage with sensor noise: the fused step runs every
/// sample after the first and stays bit for bit on the generic one.
#[test]
fn fused_step_equals_generic_step_in_the_main_mode() {
    let (mut fast, mut reference) = (main_mode(), main_mode());
    assert!(fast.lp.p.is_fused(), "the main mode runs the fused step");
    let (mut stage, mut rng, mut dac) = (Stage::new(), 0x9E37_79B9_7F4A_7C15u64, 0);
    let run = Op::Run {
        samples: 10_000,
        noise: 20,
    };
    let mut fused = 0;
    for k in 0..20 {
        fused += apply(
            &run,
            &mut fast,
            &mut reference,
            &mut stage,
            &mut rng,
            &mut dac,
        );
        assert_same(
            &fast,
            &reference,
            &format!("after {} samples", (k + 1) * 10_000),
        );
    }
    assert_eq!(fast.lp.p.state().fault, None, "{:?}", fast.lp.p.state());
    assert_eq!(fused, 200_000);
    assert_eq!(fast.lp.p.state().fault, None);
    // The loop tracks (the comparison is not between two idle pipelines).
    assert!(fast.lp.p.state().counters.samples == 200_000);
    let u = fast.lp.p.state().u_applied[0];
    assert!(u > 10.0 && u < 150.0, "{u} V");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn fused_step_equals_generic_step_under_random_operations(
        ops in proptest::collection::vec(op(), 1..40),
        seed in any::<u64>(),
    ) {
        let (mut fast, mut reference) = (main_mode(), main_mode());
        let (mut stage, mut rng, mut dac) = (Stage::new(), seed | 1, 0);
        let mut fused = 0;
        for (k, op) in ops.iter().enumerate() {
            fused += apply(op, &mut fast, &mut reference, &mut stage, &mut rng, &mut dac);
            assert_same(&fast, &reference, &format!("op {k} {op:?}"));
        }
        let _ = fused;
    }
}

/// The random operations do reach the fused step (the property above is not vacuous) and
/// leave it (faults, other modes).
#[test]
fn random_operations_cover_both_paths() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = proptest::collection::vec(op(), 20..40);
    let (mut on, mut off) = (0usize, 0usize);
    for _ in 0..16 {
        let ops = strategy.new_tree(&mut runner).unwrap().current();
        let (mut fast, mut reference) = (main_mode(), main_mode());
        let (mut stage, mut rng, mut dac) = (Stage::new(), 1, 0);
        for op in &ops {
            let before = fast.lp.p.state().counters.samples;
            let f = apply(
                op,
                &mut fast,
                &mut reference,
                &mut stage,
                &mut rng,
                &mut dac,
            );
            on += f;
            off += (fast.lp.p.state().counters.samples - before) as usize - f;
        }
    }
    assert!(on > 1_000 && off > 1_000, "fused {on}, generic {off}");
}
