//! hal-sim runs exactly the firmware's pipeline type and converter drivers: the types below
//! are the firmware aliases of `piezo_core` (`FirmwarePipeline`, `FirmwareAdc`,
//! `FirmwareDac`), instantiated on the mock SPI devices and run closed loop against the
//! simulated stage. The bench of `piezo sim` is checked to hold the very same types (a
//! compile-time check: this file does not build if they differ).

use hal_sim::mock::{
    MockAdc, MockAdcSpi, MockClock, MockCnv, MockDac, MockDacSpi, MockDelay, MockLdac,
};
use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::open_loop;
use hal_sim::sim::{
    adc_config, adc_spec, calibrate, dac_spec, pipeline_config, waves, Bench, StageInfo,
};
use hal_sim::stage::Stage;
use piezo_core::drivers::{Ad5791Config, FirmwareAdc, FirmwareDac};
use piezo_core::feedback::{Feedback, Pid, PidConfig};
use piezo_core::feedforward::{Feedforward, MultiFeedforward};
use piezo_core::pipeline::{FirmwarePipeline, Mode};

type Adc = FirmwareAdc<MockAdcSpi, MockCnv, MockDelay>;
type Dac = FirmwareDac<MockDacSpi, MockLdac, MockDelay>;

/// The bench of `piezo sim` holds the firmware types.
#[allow(dead_code)]
fn bench_uses_firmware_types(b: &Bench<1>) -> (&FirmwarePipeline, &Adc, &Dac) {
    (&b.pipeline, &b.adcs[0].driver, &b.dacs[0].driver)
}

fn pi_feedback(dt_s: f32) -> Feedback<f32> {
    Feedback::Pid(
        Pid::new(PidConfig {
            kp: 0.0,
            ki: 300.0,
            kd: 0.0,
            tf_s: 0.0,
            kb: 1.0,
            feedforward: true,
            dt_s,
        })
        .unwrap(),
    )
}

/// Runs the firmware types by hand: ADC driver -> pipeline -> DAC driver -> stage.
/// Returns the RMS tracking error (um) after the first period.
fn run(mode: Mode) -> (f64, u32) {
    let mut sc = Scenario::default();
    sc.run.duration_s = 0.2;
    let lin = calibrate(&sc).unwrap();
    let clock = MockClock::default();
    let cv = &sc.converters;
    let adc_chip = MockAdc::new(adc_spec(&sc), clock.clone());
    let delay = MockDelay(clock.clone());
    let mut adc: Adc = FirmwareAdc::new(
        adc_chip.spi(),
        adc_chip.cnv(),
        delay.clone(),
        adc_config(&sc),
    )
    .unwrap();
    adc.init().unwrap();
    let dac_chip = MockDac::new(dac_spec(&sc), clock.clone());
    let mut dac: Dac = FirmwareDac::new(
        dac_chip.spi(),
        dac_chip.ldac(),
        delay,
        Ad5791Config::DEFAULT,
    )
    .unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear: lin,
    };
    let ff = open_loop::<1>(&info).unwrap().feedforward;
    let mut p: FirmwarePipeline = FirmwarePipeline::new(
        pipeline_config::<1>(&sc, &lin),
        waves::<1>(&sc),
        ff,
        [pi_feedback(1.0 / sc.run.loop_hz as f32)],
    )
    .unwrap();
    dac.init(p.codes()[0]).unwrap();
    p.set_mode(mode);
    let mut stage = Stage::new(&sc).unwrap();
    let n = (sc.run.duration_s * sc.run.loop_hz) as usize;
    let settle = (0.1 * sc.run.loop_hz) as usize;
    let (mut se, mut m) = (0.0, 0.0);
    for k in 0..n {
        let y = stage.sensor_um(0);
        let truth = stage.position_um(0);
        adc_chip.set_input_volts((y - cv.sensor_center_um) * cv.sensor_volts_per_um);
        let code = adc.convert().unwrap();
        let out = p.step([code]);
        dac.set_code(out[0]).unwrap();
        stage.advance(&[dac_chip.output_volts()]);
        clock.set_ns(((k + 1) as f64 * 1e9 / sc.run.loop_hz) as u64);
        if k >= settle {
            let e = p.state().trace.setpoint[0].y_um as f64 - truth;
            se += e * e;
            m += 1.0;
        }
    }
    assert_eq!(adc_chip.stats().early_reads, 0);
    assert_eq!(dac_chip.stats().bad_frames, 0);
    assert_eq!(
        adc_chip.violations().count,
        0,
        "{:?}",
        adc_chip.violations()
    );
    assert_eq!(
        dac_chip.violations().count,
        0,
        "{:?}",
        dac_chip.violations()
    );
    assert_eq!(p.state().fault, None);
    ((se / m).sqrt(), p.state().counters.samples)
}

#[test]
fn firmware_types_run_closed_loop_on_the_mocks() {
    let (open, n) = run(Mode::Feedforward);
    let (closed, _) = run(Mode::ClosedLoop);
    eprintln!("rmse: linear feedforward {open:.3} um, + integral feedback {closed:.3} um");
    assert_eq!(n, 20_000);
    assert!(open > 2.0, "the hysteresis shows in open loop: {open}");
    assert!(
        closed < 0.5 * open,
        "feedback through the mocks works: {closed} vs {open}"
    );
}

#[test]
fn feedforward_enum_is_the_firmwares() {
    // The registry's controllers build the firmware's compensator type.
    let sc = Scenario::default();
    let info = StageInfo {
        scenario: &sc,
        linear: calibrate(&sc).unwrap(),
    };
    let c = open_loop::<1>(&info).unwrap();
    let _: &MultiFeedforward<f32, 1> = &c.feedforward;
    assert!(matches!(
        c.feedforward,
        MultiFeedforward::PerAxis([Feedforward::Linear(_)])
    ));
}
