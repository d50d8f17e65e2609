//! No_std mock converter chips on a simulated SPI bus, for the firmware's own drivers.
//! They keep their state in atomics (one chip of each kind per axis; the const parameter
//! `A` is the axis), so the pins and the bus of a chip are separate handles like on a board.

use core::convert::Infallible;
use core::sync::atomic::{AtomicI32, AtomicU32, Ordering::Relaxed};
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use piezo_core::drivers::{ad4000, ad5791};
use piezo_core::firmware::{ActuatorDac, PositionAdc, ADC_CONFIG, DAC_CONFIG};

/// Axes of mock chips (the xy build uses both).
const CHIPS: usize = 2;

/// The code axis 0's ADC input corresponds to now (the stage writes it every sample).
pub static INPUT_CODE: AtomicI32 = AtomicI32::new(0);
/// The same for axis 1.
static INPUT_CODE_1: AtomicI32 = AtomicI32::new(0);
/// The code sampled at the last CNV rising edge (what the next read shifts out).
static SAMPLED: [AtomicI32; CHIPS] = [const { AtomicI32::new(0) }; CHIPS];
static ADC_REG: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
/// AD5791 registers (DAC, control) and the code the output holds (set at LDAC falls).
static DAC_REG: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static DAC_CTRL: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static DAC_READ: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static DAC_OUT: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];

/// The input code of axis `a`'s ADC.
pub fn input_code(a: usize) -> &'static AtomicI32 {
    if a == 0 {
        &INPUT_CODE
    } else {
        &INPUT_CODE_1
    }
}

/// `reg[A]`, or nothing for an axis without a chip (never taken: `A < CHIPS`).
fn at<T>(reg: &'static [T; CHIPS], a: usize) -> Option<&'static T> {
    reg.get(a)
}

/// The AD4020's CNV pin: the rising edge samples the input.
pub struct Cnv<const A: usize>;
/// The AD5791's LDAC pin: the falling edge loads the DAC register into the output.
pub struct Ldac<const A: usize>;

impl<const A: usize> PinErrorType for Cnv<A> {
    type Error = Infallible;
}
impl<const A: usize> OutputPin for Cnv<A> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        if let Some(s) = at(&SAMPLED, A) {
            s.store(input_code(A).load(Relaxed), Relaxed);
        }
        Ok(())
    }
}
impl<const A: usize> PinErrorType for Ldac<A> {
    type Error = Infallible;
}
impl<const A: usize> OutputPin for Ldac<A> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        if let (Some(out), Some(reg)) = (at(&DAC_OUT, A), at(&DAC_REG, A)) {
            out.store(reg.load(Relaxed), Relaxed);
        }
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// The AD4020's serial interface: register write (`0x14`, value), register read
/// (`0x54`), and the conversion result as a left-aligned frame.
pub struct AdcSpi<const A: usize>;
/// The AD5791's serial interface: 24-bit frames, a read answered in the next frame.
pub struct DacSpi<const A: usize>;

impl<const A: usize> ErrorType for AdcSpi<A> {
    type Error = Infallible;
}
impl<const A: usize> SpiDevice for AdcSpi<A> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        let (Some(adc_reg), Some(sampled)) = (at(&ADC_REG, A), at(&SAMPLED, A)) else {
            return Ok(());
        };
        for op in ops.iter_mut() {
            match op {
                Operation::Write([ad4000::CMD_WRITE, v]) => adc_reg.store(*v as u32, Relaxed),
                Operation::Transfer(read, [ad4000::CMD_READ, ..]) => {
                    if let Some(r) = read.get_mut(1) {
                        *r = adc_reg.load(Relaxed) as u8;
                    }
                }
                Operation::Read(buf) => {
                    let frame = ad4000::encode(&ADC_CONFIG, sampled.load(Relaxed));
                    for (b, f) in buf.iter_mut().zip(frame) {
                        *b = f;
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

impl<const A: usize> ErrorType for DacSpi<A> {
    type Error = Infallible;
}
impl<const A: usize> SpiDevice for DacSpi<A> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        let (Some(dac_reg), Some(dac_ctrl), Some(dac_read)) =
            (at(&DAC_REG, A), at(&DAC_CTRL, A), at(&DAC_READ, A))
        else {
            return Ok(());
        };
        for op in ops.iter_mut() {
            match op {
                Operation::Write([a, b, c]) => {
                    let word = u32::from_be_bytes([0, *a, *b, *c]);
                    let (reg, data) = ((word >> 20) & 0b111, word & ad5791::DATA_MASK);
                    if word & ad5791::READ != 0 {
                        let v = match reg {
                            ad5791::REG_DAC => dac_reg.load(Relaxed),
                            ad5791::REG_CTRL => dac_ctrl.load(Relaxed),
                            _ => 0,
                        };
                        dac_read.store(v | (reg << 20) | ad5791::READ, Relaxed);
                    } else {
                        match reg {
                            ad5791::REG_DAC => dac_reg.store(data, Relaxed),
                            ad5791::REG_CTRL => dac_ctrl.store(data, Relaxed),
                            _ => {}
                        }
                    }
                }
                Operation::Transfer(read, _) => {
                    let b = dac_read.load(Relaxed).to_be_bytes();
                    for (r, v) in read.iter_mut().zip([b[1], b[2], b[3]]) {
                        *r = v;
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

pub type Adc<const A: usize = 0> = PositionAdc<AdcSpi<A>, Cnv<A>>;
pub type Dac<const A: usize = 0> = ActuatorDac<DacSpi<A>, Ldac<A>>;

/// The drivers on axis 0's mock chips, initialised (register written and read back).
pub fn drivers() -> (Adc, Dac) {
    drivers_of::<0>()
}

/// The drivers on axis `A`'s mock chips, initialised.
pub fn drivers_of<const A: usize>() -> (Adc<A>, Dac<A>) {
    let mut adc = Adc::new(AdcSpi, Cnv, ADC_CONFIG).expect("AD4020 driver");
    adc.init().expect("AD4020 mock answers");
    let mut dac = Dac::new(DacSpi, Ldac, DAC_CONFIG).expect("AD5791 driver");
    dac.init(0).expect("AD5791 mock answers");
    (adc, dac)
}

/// Axis `A`'s DAC output code (what the stage sees).
pub fn dac_out<const A: usize>() -> i32 {
    at(&DAC_OUT, A).map_or(0, |o| o.load(Relaxed) as i32)
}
