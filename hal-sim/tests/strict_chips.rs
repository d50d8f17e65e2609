//! The mock chips are as strict as the data sheets: the drivers' sequences pass with no
//! broken rule, and the sequences the drivers ran before issue 15 (written out here) are
//! refused, each for the rule a real part would break on.

use embedded_hal::digital::OutputPin;
use embedded_hal::spi::SpiDevice;
use hal_sim::mock::{
    AdcSpec, DacOutput, DacSpec, MockAdc, MockAdcSpi, MockClock, MockCnv, MockDac, MockDelay,
    MockSpiError,
};
use piezo_core::drivers::ad4000::{self, Ad4000Config, CodeFormat};
use piezo_core::drivers::ad5791::{self, REG_CTRL, REG_DAC, REG_SWCTRL, SW_RESET};
use piezo_core::drivers::{Ad4000, Ad5791, Ad5791Config, DacCoding, Error, SpiClock};

fn adc() -> (MockClock, MockAdc) {
    let clock = MockClock::default();
    let chip = MockAdc::new(AdcSpec::default(), clock.clone());
    (clock, chip)
}

/// A bipolar DAC (-10..10 V, offset binary): the safe code 0 V is mid-scale, not the
/// power-on code 0 (-10 V).
fn bipolar_dac() -> (MockClock, MockDac) {
    let clock = MockClock::default();
    let chip = MockDac::new(
        DacSpec {
            vrefp: 10.0,
            vrefn: -10.0,
            ..DacSpec::default()
        },
        clock.clone(),
    );
    (clock, chip)
}

const MID: i32 = 1 << 19;

/// The core's AD4020 driver on the mock chip (not yet initialised).
fn driver(clock: &MockClock, chip: &MockAdc) -> Ad4000<MockAdcSpi, MockCnv, MockDelay> {
    Ad4000::new(
        chip.spi(),
        chip.cnv(),
        MockDelay(clock.clone()),
        Ad4000Config::AD4020,
    )
    .unwrap()
}

#[test]
fn adc_driver_configures_and_converts_with_no_violation() {
    let (clock, chip) = adc();
    let mut adc = driver(&clock, &chip);
    adc.init().unwrap();
    assert_eq!(chip.register(), Ad4000Config::AD4020.register());
    let lsb = 10.0 / (1 << 20) as f64;
    for v in [-4.9, -1e-3, 0.0, 2.5, 4.99] {
        chip.set_input_volts(v);
        assert_eq!(adc.convert().unwrap(), (v / lsb).round() as i32, "{v}");
        clock.advance_ns(10_000);
    }
    // Beyond the span: the over-voltage flag in the status word fails the read.
    chip.set_input_volts(7.0);
    let e = adc.convert().unwrap_err();
    assert!(
        matches!(e, Error::Status(s) if s & ad4000::STATUS_OV != 0),
        "{e:?}"
    );
    assert_eq!(chip.violations().count, 0, "{:?}", chip.violations());
    assert_eq!(chip.stats().early_reads, 0);
}

/// The configuration register as the part has it: reset value 0xE1, reserved bits 7:5 read
/// 1 and written as 1. The driver keeps them set and compares only the mode bits; the
/// driver's write before (0x02, reserved bits 0) is refused.
#[test]
fn adc_register_resets_to_0xe1_and_keeps_its_reserved_bits() {
    let (clock, chip) = adc();
    assert_eq!(chip.register(), 0xE1);
    let mut adc = driver(&clock, &chip);
    adc.init().unwrap();
    assert_eq!(chip.register() & ad4000::REG_RESERVED, ad4000::REG_RESERVED);
    assert_eq!(
        chip.register() & ad4000::REG_WRITABLE,
        Ad4000Config::AD4020.register() & ad4000::REG_WRITABLE
    );
    assert_eq!(adc.read_register().unwrap(), chip.register());
    assert_eq!(chip.violations().count, 0, "{:?}", chip.violations());
    // The old write in a proper CNV frame: reserved bits written as 0.
    clock.advance_ns(10_000);
    let (mut cnv, mut spi) = (chip.cnv(), chip.spi());
    cnv.set_high().unwrap();
    clock.advance_ns(400);
    cnv.set_low().unwrap();
    let e = spi
        .transfer(&mut [0; 3], &[ad4000::CMD_WRITE, 0x02, 0xFF])
        .unwrap_err();
    assert!(
        matches!(e, MockSpiError::Violation(r) if r.contains("reserved bits 7:5")),
        "{e:?}"
    );
    assert_eq!(chip.register() & ad4000::REG_RESERVED, ad4000::REG_RESERVED);
}

#[test]
fn adc_straight_binary_16bit() {
    let clock = MockClock::default();
    let cfg = Ad4000Config {
        bits: 16,
        format: CodeFormat::StraightBinary,
        turbo: false,
        high_z: true,
        status: false,
        sck_hz: 40_000_000,
    };
    let chip = MockAdc::new(
        AdcSpec {
            config: cfg,
            ..AdcSpec::default()
        },
        clock.clone(),
    );
    let mut adc = Ad4000::new(chip.spi(), chip.cnv(), MockDelay(clock), cfg).unwrap();
    adc.init().unwrap();
    assert_eq!(chip.bus().hz, 40_000_000);
    chip.set_input_volts(2.5);
    assert_eq!(adc.convert().unwrap(), 32768);
    assert_eq!(chip.violations().count, 0);
}

#[test]
fn adc_driver_notices_a_failed_bus() {
    let (clock, chip) = adc();
    chip.fail_transactions(1);
    let mut adc = Ad4000::new(
        chip.spi(),
        chip.cnv(),
        MockDelay(clock),
        Ad4000Config::AD4020,
    )
    .unwrap();
    assert!(adc.init().is_err());
}

/// The AD4000 init before issue 15: the register written and read back with CNV low since
/// power-up (the board's timer held CNV), i.e. outside any CNV frame.
#[test]
fn old_adc_init_is_refused_outside_a_cnv_frame() {
    let (_clock, chip) = adc();
    let mut spi = chip.spi();
    let reg = Ad4000Config::AD4020.register();
    let e = spi.write(&[ad4000::CMD_WRITE, reg]).unwrap_err();
    assert!(
        matches!(e, MockSpiError::Violation(r) if r.starts_with("register access outside a CNV frame")),
        "{e:?}"
    );
    let mut buf = [0u8; 2];
    let e = spi
        .transfer(&mut buf, &[ad4000::CMD_READ, 0xFF])
        .unwrap_err();
    assert!(matches!(e, MockSpiError::Violation(r) if r.starts_with("register access outside")));
    assert_eq!(
        chip.register(),
        ad4000::REG_RESET,
        "the part ignored the write"
    );
    assert_eq!(chip.violations().count, 2);
}

#[test]
fn adc_read_before_t_conv_is_refused() {
    let (clock, chip) = adc();
    let mut adc = driver(&clock, &chip);
    adc.init().unwrap();
    clock.advance_ns(10_000);
    adc.start_conversion().unwrap();
    clock.advance_ns(319);
    let e = adc.read().unwrap_err();
    assert!(
        matches!(e, Error::Pin(p) if p.0.starts_with("CNV fell before t_CONV")),
        "{e:?}"
    );
    assert_eq!(chip.violations().first.unwrap().measured, 319);
}

/// The loop's read before issue 15 was a plain `read`, whose MOSI words the bus chooses (the
/// H743 adapter sent zeros): SDI is then low at the next CNV edge, the part enters
/// daisy-chain mode and the following 3-wire read is refused.
#[test]
fn adc_three_wire_reads_need_sdi_high_at_the_cnv_edge() {
    let (clock, chip) = adc();
    let mut adc = driver(&clock, &chip);
    adc.init().unwrap();
    let mut cnv = chip.cnv();
    let mut spi = chip.spi();
    for k in 0..2 {
        clock.advance_ns(10_000);
        cnv.set_high().unwrap();
        clock.advance_ns(400);
        cnv.set_low().unwrap();
        let r = spi.read(&mut [0u8; 3]);
        if k == 0 {
            r.unwrap();
        } else {
            let e = r.unwrap_err();
            assert!(
                matches!(e, MockSpiError::Violation(r) if r.starts_with("frame in daisy-chain mode")),
                "{e:?}"
            );
        }
    }
    // Refused too (daisy-chain frame), but MOSI is driven high: the next CNV edge finds CS
    // mode and the driver's read (SDI held high) works again.
    spi.write(&[0xFF]).unwrap_err();
    assert_eq!(chip.violations().count, 2);
    clock.advance_ns(10_000);
    assert_eq!(adc.convert().unwrap(), 0);
    assert_eq!(chip.violations().count, 2);
}

#[test]
fn adc_frame_with_cnv_high_or_sck_too_fast_is_refused() {
    let (clock, chip) = adc();
    let mut adc = driver(&clock, &chip);
    adc.init().unwrap();
    adc.start_conversion().unwrap();
    let e = chip.spi().transfer(&mut [0; 3], &[0xFF; 3]).unwrap_err();
    assert!(
        matches!(e, MockSpiError::Violation(r) if r.starts_with("SPI frame while CNV is high"))
    );
    clock.advance_ns(400);
    chip.cnv().set_low().unwrap();
    let mut spi = chip.spi();
    assert_eq!(
        spi.set_sclk_max_hz(200_000_000),
        50_000_000,
        "the bus tops out at 50 MHz"
    );
    let fast = MockAdc::new(
        AdcSpec {
            bus: hal_sim::mock::BusClock {
                hz: 25_000_000,
                max_hz: 200_000_000,
            },
            ..AdcSpec::default()
        },
        clock.clone(),
    );
    let mut spi = fast.spi();
    spi.set_sclk_max_hz(150_000_000);
    let e = spi.write(&[0xFF]).unwrap_err();
    assert!(matches!(e, MockSpiError::Violation(r) if r.starts_with("SCK above 102 MHz")));
    assert_eq!(fast.violations().first.unwrap().measured, 150_000_000);
}

#[test]
fn dac_driver_brings_the_output_up_at_the_safe_code() {
    let (clock, chip) = bipolar_dac();
    let mut dac = Ad5791::new(
        chip.spi(),
        chip.ldac(),
        MockDelay(clock.clone()),
        Ad5791Config::DEFAULT,
    )
    .unwrap();
    assert_eq!(
        chip.output(),
        DacOutput::Clamped,
        "clamped to ground at power-up"
    );
    clock.advance_ns(1000);
    dac.init(MID).unwrap();
    assert_eq!(chip.violations().count, 0, "{:?}", chip.violations());
    // Clamped from power-on until released straight at the safe code (0 V).
    let states: Vec<DacOutput> = chip.output_log().into_iter().map(|(_, s)| s).collect();
    assert_eq!(states, [DacOutput::Clamped, DacOutput::Driven(MID as u32)]);
    assert!(chip.output_volts().abs() < 1e-4);
    assert_eq!(chip.bus().hz, 25_000_000, "back at the write rate");
    assert_eq!(dac.read_code().unwrap(), MID);
    dac.write_code(0xFFFFF).unwrap();
    assert!(chip.output_volts().abs() < 1e-4, "waits for LDAC");
    dac.load().unwrap();
    assert!((chip.output_volts() - 10.0).abs() < 1e-4);
    assert_eq!(dac.read_register(REG_DAC).unwrap(), 0xFFFFF);
    assert_eq!(chip.stats().bad_frames, 0);
    assert_eq!(chip.violations().count, 0);
}

/// SYNC stays high for `t6` = 48 ns between two frames: the driver waits it before every
/// frame (init, a read-back right after the loop's write and load, as `selftest` does);
/// two frames back to back, as the driver sent them before, are refused.
#[test]
fn dac_sync_high_t6_between_frames() {
    let (clock, chip) = bipolar_dac();
    let mut dac = Ad5791::new(
        chip.spi(),
        chip.ldac(),
        MockDelay(clock.clone()),
        Ad5791Config::DEFAULT,
    )
    .unwrap();
    dac.init(MID).unwrap();
    dac.set_code(MID + 5).unwrap();
    assert_eq!(dac.read_code().unwrap(), MID + 5);
    assert_eq!(chip.violations().count, 0, "{:?}", chip.violations());
    let mut spi = chip.spi();
    clock.advance_ns(1000);
    spi.write(&ad5791::write_frame(REG_DAC, 7)).unwrap();
    clock.advance_ns(47);
    let e = spi.write(&ad5791::write_frame(REG_DAC, 8)).unwrap_err();
    assert!(
        matches!(e, MockSpiError::Violation(r) if r.starts_with("SYNC high shorter than t6")),
        "{e:?}"
    );
    assert_eq!(chip.violations().first.unwrap().measured, 47);
    clock.advance_ns(48);
    spi.write(&ad5791::write_frame(REG_DAC, 9)).unwrap();
}

#[test]
fn dac_twos_complement_coding() {
    let (clock, chip) = bipolar_dac();
    let cfg = Ad5791Config {
        coding: DacCoding::TwosComplement,
        rbuf: true,
        lincomp: 12,
        sclk_hz: 20_000_000,
    };
    let mut dac = Ad5791::new(chip.spi(), chip.ldac(), MockDelay(clock), cfg).unwrap();
    dac.init(0).unwrap();
    assert!(chip.output_volts().abs() < 1e-4);
    dac.set_code(-(1 << 19)).unwrap();
    assert!((chip.output_volts() + 10.0).abs() < 1e-9);
    assert_eq!(dac.read_code().unwrap(), -(1 << 19));
    assert_eq!(chip.violations().count, 0);
}

/// The AD5791 init before issue 15, written out: software reset, the control register
/// released at once (output driven at the power-on code), the initial code written and
/// loaded with a zero-width LDAC pulse, and the control register read back at the 25 MHz
/// write clock. Each step breaks a rule of the part.
#[test]
fn old_dac_init_is_refused() {
    let (clock, chip) = bipolar_dac();
    let mut spi = chip.spi();
    let mut ldac = chip.ldac();
    let ctrl = Ad5791Config::DEFAULT.control();
    // (SYNC high for t6 between the frames here: the rules below are the ones tested.)
    spi.write(&ad5791::write_frame(REG_SWCTRL, SW_RESET))
        .unwrap();
    clock.advance_ns(100);
    spi.write(&ad5791::write_frame(REG_CTRL, ctrl)).unwrap();
    let first = chip.violations().first.unwrap();
    assert!(
        first
            .rule
            .starts_with("output released at the power-on code"),
        "{first:?}"
    );
    assert_eq!(
        chip.output(),
        DacOutput::Driven(0),
        "-10 V on the amplifier input"
    );
    clock.advance_ns(100);
    spi.write(&ad5791::write_frame(REG_DAC, MID as u32))
        .unwrap();
    ldac.set_low().unwrap();
    let e = ldac.set_high().unwrap_err();
    assert!(e.0.starts_with("LDAC low pulse shorter than t10"), "{e:?}");
    clock.advance_ns(100);
    let e = spi.write(&[0xA0, 0, 0]).unwrap_err(); // read CTRL at 25 MHz
    assert!(
        matches!(e, MockSpiError::Violation(r) if r.starts_with("read-back SCLK above 10.87 MHz")),
        "{e:?}"
    );
    assert_eq!(chip.violations().count, 3);
}

#[test]
fn dac_floating_output_and_fast_write_clock_are_refused() {
    let (clock, chip) = bipolar_dac();
    let mut spi = chip.spi();
    spi.write(&ad5791::write_frame(REG_CTRL, ad5791::CTRL_DACTRI))
        .unwrap();
    assert_eq!(chip.output(), DacOutput::Floating);
    assert!(chip
        .violations()
        .first
        .unwrap()
        .rule
        .starts_with("output floating"));
    // A bus that can run 50 MHz, asked for 30 MHz: every frame is refused.
    clock.advance_ns(100);
    assert_eq!(spi.set_sclk_max_hz(30_000_000), 30_000_000);
    let e = spi.write(&ad5791::write_frame(REG_DAC, 1)).unwrap_err();
    assert!(matches!(e, MockSpiError::Violation(r) if r.starts_with("SCLK above 25 MHz")));
    // The driver asks for at most 25 MHz whatever its config says.
    let cfg = Ad5791Config {
        sclk_hz: 40_000_000,
        ..Ad5791Config::DEFAULT
    };
    let (clock2, chip2) = bipolar_dac();
    let mut dac = Ad5791::new(chip2.spi(), chip2.ldac(), MockDelay(clock2), cfg).unwrap();
    dac.init(MID).unwrap();
    assert_eq!(chip2.bus().hz, 25_000_000);
    assert_eq!(chip2.violations().count, 0);
}
