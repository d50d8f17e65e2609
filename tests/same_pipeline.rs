//! The firmware binary and hal-sim run the same pipeline type and the same converter
//! drivers (issue #3). The firmware's board-independent module (`piezo_core::firmware`,
//! which both boards build on) is used here as the binaries use it; its pipeline and
//! driver types are compared by `TypeId` with the fields of the bench `piezo sim` runs. The
//! machine-code side (the ELF holds the pipeline step and the driver code in the control
//! interrupt) is checked by `.ci/test.d/20-firmware.sh`.

use hal_sim::mock::{MockAdcSpi, MockCnv, MockDacSpi, MockDelay, MockLdac};
use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::open_loop;
use hal_sim::sim::{adc_config, calibrate, Bench, StageInfo};
use piezo_core::drivers::{Ad4000, Ad5791};
use piezo_core::firmware::{self as control, OnChip};
use piezo_core::pipeline::Pipeline;
use std::any::{Any, TypeId};

fn type_of<T: Any>(_: &T) -> TypeId {
    TypeId::of::<T>()
}

fn bench_of<const N: usize>(sc: Scenario) -> (Scenario, Bench<N>) {
    let linear = calibrate(&sc).unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear,
    };
    let controller = open_loop::<N>(&info).unwrap();
    let bench = Bench::new(&sc, controller, &linear).unwrap();
    (sc, bench)
}

fn bench() -> (Scenario, Bench<1>) {
    bench_of(Scenario::default())
}

/// hal-sim's XY scanner: two axes on a raster.
fn bench_xy() -> (Scenario, Bench<2>) {
    let sc = Scenario::from_toml("[stage]\naxes = 2\n[reference]\nwave = \"raster\"").unwrap();
    bench_of(sc)
}

#[test]
fn firmware_and_hal_sim_run_the_same_pipeline_type() {
    let ctl = control::Ctl::<OnChip>::new(control::c(control::SAMPLE_HZ as f64));
    let firmware = type_of(&ctl.lp.p);
    // The firmware's axis count (1, or 2 with `--features xy`) picks hal-sim's bench.
    let sim = if control::AXES == 2 {
        type_of(&bench_xy().1.pipeline)
    } else {
        type_of(&bench().1.pipeline)
    };
    assert_eq!(firmware, sim, "pipeline types differ");
    assert_eq!(firmware, TypeId::of::<control::LoopPipeline>());
    // The comparison tells types apart: another number type or axis count fails it.
    assert_ne!(firmware, TypeId::of::<Pipeline<f64, 1>>());
    assert_ne!(firmware, TypeId::of::<Pipeline<f64, 2>>());
    let other_axes = if control::AXES == 2 {
        TypeId::of::<Pipeline<f32, 1>>()
    } else {
        TypeId::of::<Pipeline<f32, 2>>()
    };
    assert_ne!(firmware, other_axes);
}

/// The xy build's pipeline type (`FirmwarePipeline2`) is the one hal-sim's 2-axis
/// scenarios (raster, Lissajous) run, whichever build this test is.
#[test]
fn the_xy_pipeline_is_hal_sims_two_axis_pipeline() {
    let (_, bench) = bench_xy();
    assert_eq!(
        type_of(&bench.pipeline),
        TypeId::of::<piezo_core::pipeline::FirmwarePipeline2>()
    );
    assert_ne!(
        type_of(&bench.pipeline),
        TypeId::of::<piezo_core::pipeline::FirmwarePipeline>()
    );
}

#[test]
fn firmware_and_hal_sim_run_the_same_converter_drivers() {
    let (sc, bench) = bench();
    // The firmware's driver aliases, on hal-sim's mock buses and pins, are the types of the
    // bench's drivers: the same generic driver code runs on the board's buses.
    let adc = TypeId::of::<control::PositionAdc<MockAdcSpi, MockCnv, MockDelay>>();
    let dac = TypeId::of::<control::ActuatorDac<MockDacSpi, MockLdac, MockDelay>>();
    assert_eq!(
        adc,
        type_of(&bench.adcs[0].driver),
        "ADC driver types differ"
    );
    assert_eq!(
        dac,
        type_of(&bench.dacs[0].driver),
        "DAC driver types differ"
    );
    assert_eq!(adc, TypeId::of::<Ad4000<MockAdcSpi, MockCnv, MockDelay>>());
    assert_eq!(dac, TypeId::of::<Ad5791<MockDacSpi, MockLdac, MockDelay>>());
    assert_ne!(adc, dac);
    // ... configured as the mock chips are: the AD4020 of the default scenario, the AD5791
    // in the configuration the bench initialises.
    assert_eq!(control::ADC_CONFIG, adc_config(&sc));
    assert_eq!(*bench.adcs[0].driver.config(), control::ADC_CONFIG);
    assert_eq!(*bench.dacs[0].driver.config(), control::DAC_CONFIG);
}
