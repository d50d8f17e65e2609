//! A position channel that fails mid-stroke reaches the safe state within a bounded number
//! of samples: the firmware's loop (`Loop<SpiPair>`, the main mode ff+hgo-robust on
//! IMS-CBW in closed loop) on the firmware's AD4020 driver and hal-sim's mock chip, driving
//! a CBW stage with the firmware's lag, with each fault of [`AdcFault`] injected mid-stroke.
//! One test per fault; a last test shows what the loop did without the checks (status bits
//! off, no stuck-code limit, no guard band): SDO held low reads 50 um, mid-stroke, and
//! nothing notices.

use hal_sim::mock::{AdcFault, AdcSpec, MockAdc, MockClock, MockDelay};
use hal_sim::sim::SimAdc;
use piezo_core::drivers::Ad4000Config;
use piezo_core::firmware::{Loop, SpiPair, ADC_CONFIG, SAMPLE_HZ, SPI_CENTER_UM, STAGE_POLE_PER_S};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use piezo_core::pipeline::{Fault, Wave};

/// The stage: CBW set 1 of the 000 backup slide with the firmware's lag pole, as the QEMU
/// board's (without creep).
struct Stage {
    model: Cbw<f64>,
    state: BwState<f64>,
    lag: f64,
    y_um: f64,
}

struct Bench {
    clock: MockClock,
    chip: MockAdc,
    adc: SimAdc,
    lp: Loop<SpiPair>,
    stage: Stage,
    /// Samples run.
    k: u64,
}

const DT_S: f64 = 1.0 / SAMPLE_HZ as f64;
/// AD4020 input (V) per um: +-5 V over the 120 um span.
const VOLTS_PER_UM: f64 = 10.0 / 120.0;

fn bench(config: Ad4000Config) -> Bench {
    let clock = MockClock::default();
    let chip = MockAdc::new(
        AdcSpec {
            config,
            noise_lsb: 1.0,
            ..AdcSpec::default()
        },
        clock.clone(),
    );
    let mut adc = SimAdc::new(chip.spi(), chip.cnv(), MockDelay(clock.clone()), config).unwrap();
    adc.init().unwrap();
    let mut lp = Loop::<SpiPair>::new(SAMPLE_HZ as f32);
    lp.set_ff("ims-cbw").unwrap();
    lp.set_law("ff+hgo-robust").unwrap();
    lp.p.set_wave(0, Wave::sine(12.0, 8.0, 200.0)).unwrap();
    let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
    let stage = Stage {
        state: model.init(0.0),
        model,
        lag: 1.0 - (-STAGE_POLE_PER_S * DT_S).exp(),
        y_um: 0.0,
    };
    Bench {
        clock,
        chip,
        adc,
        lp,
        stage,
        k: 0,
    }
}

impl Bench {
    /// One sample: the stage at its position, the conversion, the loop's step, the DAC code
    /// to the stage (0 V while the amplifier is off: a fault latched). Returns the volts
    /// commanded.
    fn step(&mut self) -> f64 {
        self.clock.advance_ns(10_000);
        self.chip
            .set_input_volts((self.stage.y_um - SPI_CENTER_UM) * VOLTS_PER_UM);
        let code = self.adc.convert().unwrap_or(i32::MIN);
        let dac = self.lp.step([code])[0];
        let amp_on = self.lp.p.state().fault.is_none();
        let u = if amp_on {
            dac as f64 * 150.0 / ((1 << 20) - 1) as f64
        } else {
            0.0
        };
        let s = &mut self.stage;
        let y = s.model.step(&mut s.state, u, DT_S);
        s.y_um += s.lag * (y - s.y_um);
        self.k += 1;
        u
    }

    /// Runs `n` healthy samples: no fault may latch (the checks hold no false alarm).
    fn healthy(&mut self, n: u64) {
        for _ in 0..n {
            self.step();
            assert_eq!(self.lp.p.state().fault, None, "false alarm at {}", self.k);
        }
        let y = self.stage.y_um;
        assert!((2.0..22.0).contains(&y), "tracking mid-stroke: {y} um");
    }

    /// Injects `fault` and returns the samples until the safe state latched (the first
    /// faulty conversion counts 1), at most `limit`.
    fn samples_to_safe(&mut self, fault: AdcFault, limit: u64) -> (u64, Fault) {
        self.chip.set_fault(Some(fault));
        for n in 1..=limit {
            self.step();
            if let Some(f) = self.lp.p.state().fault {
                return (n, f);
            }
        }
        panic!("{fault:?}: no safe state within {limit} samples");
    }
}

fn run(fault: AdcFault, bound: u64) -> Fault {
    let mut b = bench(ADC_CONFIG);
    b.healthy(20_000);
    let (n, f) = b.samples_to_safe(fault, 10 * bound);
    assert!(
        n <= bound,
        "{fault:?}: safe after {n} samples, bound {bound}"
    );
    // The safe state holds: the amplifier stays off while the fault lasts.
    for _ in 0..1000 {
        b.step();
        assert!(b.lp.p.state().fault.is_some());
    }
    f
}

#[test]
fn sdo_stuck_low_is_safe_at_once() {
    // All zeros: the status word's mode bits are gone.
    assert_eq!(run(AdcFault::StuckLow, 1), Fault::SensorRange { axis: 0 });
}

#[test]
fn sdo_stuck_high_is_safe_at_once() {
    // All ones: the over-voltage flag is set.
    assert_eq!(run(AdcFault::StuckHigh, 1), Fault::SensorRange { axis: 0 });
}

#[test]
fn floating_input_is_safe_within_the_stuck_limit() {
    let limit = Loop::<SpiPair>::new(SAMPLE_HZ as f32).stuck_limit as u64;
    assert!(limit > 0, "the stuck-code detector is on by default");
    assert_eq!(
        run(AdcFault::Floating, limit),
        Fault::SensorStuck { axis: 0 }
    );
}

#[test]
fn disconnected_sensor_is_safe_at_once_by_the_guard_band() {
    // 97 % of full scale is inside the span (no over-voltage flag) but inside the guard band.
    assert_eq!(
        run(AdcFault::Disconnected, 1),
        Fault::SensorRange { axis: 0 }
    );
}

/// Without the checks (the driver and the loop as they were: no status bits, no stuck-code
/// limit, no guard band) SDO held low reads as 50 um, mid-stroke: no fault, the amplifier
/// stays on and the closed loop acts on a position the stage is nowhere near.
#[test]
fn without_the_checks_a_stuck_sdo_drives_the_stage() {
    let mut b = bench(Ad4000Config {
        status: false,
        ..ADC_CONFIG
    });
    b.lp.stuck_limit = 0;
    b.lp.p
        .set_sensor(
            0,
            <SpiPair as piezo_core::firmware::Converters>::sensor(0.0),
        )
        .unwrap();
    b.healthy(20_000);
    b.chip.set_fault(Some(AdcFault::StuckLow));
    for _ in 0..20_000 {
        b.step();
    }
    assert_eq!(b.lp.p.state().fault, None, "nothing noticed");
    let seen = b.lp.p.state().trace.y_um[0] as f64;
    assert!((seen - SPI_CENTER_UM).abs() < 1e-3, "reads {seen} um");
    let y = b.stage.y_um;
    assert!((y - seen).abs() > 25.0, "the stage is at {y} um");
}
