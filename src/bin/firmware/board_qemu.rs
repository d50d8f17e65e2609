//! QEMU `mps2-an386` (Cortex-M4F) board: the RTIC app boots in CI with a simulated stage.
//!
//! * SysTick (25 MHz in QEMU's mps2 model) fires at the sample rate and runs the control
//!   step at the highest priority. The stage is [`SimStage`]: the CBW model of the core plus
//!   a first-order lag. It sits behind the firmware's real converter drivers: the control
//!   task runs `Ad4000::start_conversion` + `Ad4000::read` and `Ad5791::set_code` (the
//!   drivers of `piezo_core::drivers`, the ones hal-sim runs) over the no_std mock chips of
//!   [`chips`] (an AD4020 whose CNV edge samples the stage, an AD5791 whose LDAC edge sets
//!   the stage's voltage), with the 20-bit codes of the SPI converter pair. With feature
//!   `xy` there are two identical, independent stages, each behind its own pair of chips
//!   ([`Io`]).
//! * The CMSDK UART0 (0x4000_4000, QEMU `-serial`) carries the command protocol, polled from
//!   the idle task (lowest priority).
//! * defmt logs go out over semihosting (decode with `defmt-print -e <elf>`).
//! * Before the loop starts, `init` measures the instructions per control step of every
//!   feedback law x feedforward combination (run QEMU with `-icount shift=0`: one instruction
//!   per virtual ns, so SysTick ticks over N steps count instructions; a loop of known length
//!   calibrates ticks to instructions). The `bench` command prints that table. The table
//!   counts the pipeline step (ADC code in, DAC code out) without the driver calls; one
//!   extra line counts the driver path per sample (both drivers and the mock chips).
//! * The host ends the run: the line `exit` (this board's test-harness command, not part of
//!   the protocol) makes the app exit through semihosting with status 0 once at least
//!   [`PERIODS_MIN`] periods have run; a host that kills QEMU ends it too. If no command
//!   arrives within [`PERIODS_MAX`] periods it exits with status 1. Nothing depends on how
//!   long the host is silent: a busy host may pause between `piezo serial` calls for any
//!   time without ending the session.

use crate::control::AXES;
/// Sample rate of the control loop (Hz of virtual time): 100 kHz in f32, 16 384 Hz in Q16.16.
pub use crate::control::SAMPLE_HZ;
/// SysTick clock of QEMU's mps2 machines (Hz).
pub const SYSTICK_HZ: u32 = 25_000_000;
/// Control periods to run before exiting.
pub const PERIODS_MIN: u32 = 10_000;
/// Give up (exit 1) when no command was answered after this many periods.
pub const PERIODS_MAX: u32 = 300_000;
/// The harness line that ends the run (after [`PERIODS_MIN`] periods).
const EXIT_LINE: &[u8] = b"exit";
/// Steps per benchmark row.
pub const BENCH_STEPS: usize = 2_000;

/// The "device" RTIC needs: no vendor interrupts are used, only SysTick.
pub mod pac {
    /// QEMU's NVIC implements 8 bits; RTIC only needs 3 levels here.
    pub const NVIC_PRIO_BITS: u8 = 3;
}

/// CMSDK APB UART0 of the mps2 machines.
mod uart {
    const BASE: usize = 0x4000_4000;
    const DATA: usize = BASE;
    const STATE: usize = BASE + 0x4;
    const CTRL: usize = BASE + 0x8;
    const BAUDDIV: usize = BASE + 0x10;
    const TX_FULL: u32 = 1;
    const RX_FULL: u32 = 2;

    #[allow(unsafe_code)]
    fn read(addr: usize) -> u32 {
        // SAFETY: a CMSDK UART register of the mps2 memory map, always mapped.
        unsafe { core::ptr::read_volatile(addr as *const u32) }
    }
    #[allow(unsafe_code)]
    fn write(addr: usize, v: u32) {
        // SAFETY: as above; only the UART owns these addresses.
        unsafe { core::ptr::write_volatile(addr as *mut u32, v) }
    }

    /// 115200 Bd at 25 MHz, transmitter and receiver on, no interrupts.
    pub fn init() {
        write(BAUDDIV, 217);
        write(CTRL, 0b11);
    }

    pub fn try_read() -> Option<u8> {
        if read(STATE) & RX_FULL != 0 {
            Some(read(DATA) as u8)
        } else {
            None
        }
    }

    pub fn write_bytes(bytes: &[u8]) {
        for &b in bytes {
            // Bounded wait: QEMU drains the holding register at once.
            for _ in 0..100_000 {
                if read(STATE) & TX_FULL == 0 {
                    break;
                }
            }
            write(DATA, b as u32);
        }
    }

    pub fn line(s: &str) {
        write_bytes(s.as_bytes());
        write_bytes(b"\n");
    }
}

use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};

/// The stage the converters see: CBW hysteresis (000 eq. 1-2) followed by a first-order
/// lag (mechanical bandwidth), driven by a 20-bit DAC code over 0..150 V and sampled as an
/// AD4020 code (two's complement, the full scale over [`crate::control::SPI_SPAN_UM`]).
pub struct SimStage {
    model: Cbw<f32>,
    state: BwState<f32>,
    /// Lag factor per sample, `1 - exp(-2 pi f_c / f_s)`.
    lag: f32,
    y_um: f32,
    volts_per_code: f32,
    codes_per_um: f32,
}

impl SimStage {
    /// 000 backup slide parameter set 1, lag pole [`crate::control::STAGE_POLE_PER_S`].
    pub fn new(sample_hz: f32) -> Self {
        let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("CBW parameter set 1 is valid");
        let lag = 1.0 - libm::expf(-(crate::control::STAGE_POLE_PER_S as f32) / sample_hz);
        Self {
            model,
            state: model.init(0.0),
            lag,
            y_um: 0.0,
            volts_per_code: 150.0 / crate::control::DAC_FULL as f32,
            codes_per_um: (1u32 << crate::control::ADC_BITS) as f32
                / crate::control::SPI_SPAN_UM as f32,
        }
    }

    /// DAC code in, ADC code out (one sample).
    pub fn step(&mut self, dac_code: i32) -> i32 {
        let u = dac_code as f32 * self.volts_per_code;
        let y = self.model.step(&mut self.state, u, 1.0 / SAMPLE_HZ as f32);
        self.y_um += self.lag * (y - self.y_um);
        let half = (1i32 << (crate::control::ADC_BITS - 1)) as f32;
        let centre = crate::control::SPI_CENTER_UM as f32;
        let code = libm::floorf((self.y_um - centre) * self.codes_per_um + 0.5);
        if code >= half - 1.0 {
            half as i32 - 1
        } else if code >= -half {
            code as i32
        } else {
            -half as i32
        }
    }
}

/// No_std mock converter chips on a simulated SPI bus, for the firmware's own drivers.
/// They keep their state in atomics (one chip of each kind per axis; the const parameter
/// `A` is the axis), so the pins and the bus of a chip are separate handles like on a board.
pub mod chips {
    use crate::control::{ADC_CONFIG, DAC_CONFIG};
    use core::convert::Infallible;
    use core::sync::atomic::{AtomicI32, AtomicU32, Ordering::Relaxed};
    use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
    use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
    use piezo_core::drivers::{ad4000, ad5791};

    /// Axes of mock chips (the xy build uses both).
    const CHIPS: usize = 2;
    const I0: AtomicI32 = AtomicI32::new(0);
    const U0: AtomicU32 = AtomicU32::new(0);

    /// The code axis 0's ADC input corresponds to now (the stage writes it every sample).
    pub static INPUT_CODE: AtomicI32 = AtomicI32::new(0);
    /// The same for axis 1.
    static INPUT_CODE_1: AtomicI32 = AtomicI32::new(0);
    /// The code sampled at the last CNV rising edge (what the next read shifts out).
    static SAMPLED: [AtomicI32; CHIPS] = [I0; CHIPS];
    static ADC_REG: [AtomicU32; CHIPS] = [U0; CHIPS];
    /// AD5791 registers (DAC, control) and the code the output holds (set at LDAC falls).
    static DAC_REG: [AtomicU32; CHIPS] = [U0; CHIPS];
    static DAC_CTRL: [AtomicU32; CHIPS] = [U0; CHIPS];
    static DAC_READ: [AtomicU32; CHIPS] = [U0; CHIPS];
    static DAC_OUT: [AtomicU32; CHIPS] = [U0; CHIPS];

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

    pub type Adc<const A: usize = 0> = crate::control::PositionAdc<AdcSpi<A>, Cnv<A>>;
    pub type Dac<const A: usize = 0> = crate::control::ActuatorDac<DacSpi<A>, Ldac<A>>;

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
}

/// The simulated stage and the converter drivers of every axis the build drives (xy build:
/// two independent, identical stages, each behind its own AD4020/AD5791 pair).
pub struct Io {
    stage: [SimStage; AXES],
    adc: chips::Adc<0>,
    dac: chips::Dac<0>,
    #[cfg(feature = "xy")]
    adc1: chips::Adc<1>,
    #[cfg(feature = "xy")]
    dac1: chips::Dac<1>,
}

impl Io {
    pub fn new() -> Self {
        let (adc, dac) = chips::drivers_of::<0>();
        #[cfg(feature = "xy")]
        let (adc1, dac1) = chips::drivers_of::<1>();
        Self {
            stage: core::array::from_fn(|_| SimStage::new(SAMPLE_HZ as f32)),
            adc,
            dac,
            #[cfg(feature = "xy")]
            adc1,
            #[cfg(feature = "xy")]
            dac1,
        }
    }

    /// One sample of every axis: the stage moves under its DAC's output, the ADC driver
    /// samples and reads it. A failed read gives a code outside every sensor window (the
    /// safe state).
    #[inline(always)]
    pub fn read(&mut self) -> [i32; AXES] {
        let mut codes = [i32::MIN; AXES];
        let (mut stage, mut code) = (self.stage.iter_mut(), codes.iter_mut());
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc);
        }
        #[cfg(feature = "xy")]
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc1);
        }
        codes
    }

    /// Writes and loads every axis' DAC code; a failed write reports the code its DAC
    /// still holds.
    #[inline(always)]
    pub fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
        let mut held = [None; AXES];
        let (mut code, mut h) = (codes.iter(), held.iter_mut());
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac.set_code(*c).err().map(|_| chips::dac_out::<0>());
        }
        #[cfg(feature = "xy")]
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac1.set_code(*c).err().map(|_| chips::dac_out::<1>());
        }
        held
    }
}

/// One axis: stage step, conversion, read. Not inlined: one call per axis, and the ELF's
/// debug info keeps naming `Ad4000::read` in the control interrupt (`.ci/firmware-code.py`).
#[inline(never)]
fn read_axis<const A: usize>(stage: &mut SimStage, adc: &mut chips::Adc<A>) -> i32 {
    let y = stage.step(chips::dac_out::<A>());
    chips::input_code(A).store(y, core::sync::atomic::Ordering::Relaxed);
    match adc.start_conversion() {
        Ok(()) => adc.read().unwrap_or(i32::MIN),
        Err(_) => i32::MIN,
    }
}

/// Instruction counts per control step, measured in `init`.
pub mod bench {
    use super::{uart, SimStage, BENCH_STEPS, SAMPLE_HZ};
    use crate::control::{c, Ctl, AXES, FFS, LAWS};
    use core::hint::black_box;
    use cortex_m::peripheral::{syst::SystClkSource, SYST};
    use piezo_core::command::Reply;
    use piezo_core::pipeline::Wave;

    pub const ROWS: usize = LAWS.len() * FFS.len();

    /// Profiling build (`PIEZO_BENCH_ONLY="<law> <ff>"` at compile time): the bench runs that
    /// row only, brackets its timed loop with calls to [`mark`] and exits QEMU after it, so
    /// a `-singlestep -d exec,nochain` log holds one row (see the README's profile command).
    const ONLY: Option<&str> = option_env!("PIEZO_BENCH_ONLY");

    /// Marks the start (1) and end (2) of a timed loop in an execution log.
    #[inline(never)]
    pub fn mark(k: u32) {
        black_box(k);
    }

    fn selected(law: &str, ff: &str) -> bool {
        match ONLY {
            None => true,
            Some(o) => o.split_once(' ') == Some((law, ff)),
        }
    }

    #[derive(Clone, Copy, Debug, Default)]
    pub struct Row {
        pub law: &'static str,
        pub ff: &'static str,
        /// Instructions per step x 100.
        pub instr_x100: u32,
        /// Worst single step (instructions, SysTick resolution).
        pub max_instr: u32,
        /// The law or compensator could not be configured for this number type.
        pub unsupported: bool,
    }

    pub struct Table {
        pub rows: [Row; ROWS],
        /// Instructions per SysTick tick x 1000 (calibration, 40 000 expected).
        pub instr_per_tick_x1000: u32,
        /// Loop overhead subtracted (ticks over BENCH_STEPS).
        pub overhead_ticks: u32,
        /// The driver path per sample x 100: `Ad4000::start_conversion` + `Ad4000::read` +
        /// `Ad5791::set_code`, mock chips included (not part of the rows).
        pub drivers_x100: u32,
    }

    /// Ticks elapsed on the down-counting SysTick between two readings.
    fn ticks(start: u32, end: u32) -> u32 {
        start.wrapping_sub(end) & 0x00FF_FFFF
    }

    /// `n` iterations of a two-instruction loop (`subs` + `bne`).
    #[allow(unsafe_code)]
    fn known_loop(n: u32) {
        // SAFETY: register-only countdown, no memory access.
        unsafe {
            core::arch::asm!("1:", "subs {n}, {n}, #1", "bne 1b", n = inout(reg) n => _,
                options(nomem, nostack));
        }
    }

    /// A loop with `ff` and `law` (`open-loop` means the feedforward alone) on a 5 um,
    /// 100 Hz sine around 10 um.
    fn configured(law: &str, ff: &str) -> Option<Ctl> {
        let mut ctl = Ctl::new(c(SAMPLE_HZ as f64));
        ctl.lp.set_ff(ff).ok()?;
        let law = if law == "open-loop" {
            "feedforward"
        } else {
            law
        };
        ctl.lp.set_law(law).ok()?;
        ctl.lp
            .p
            .set_wave(
                0,
                Wave::Sine {
                    offset_um: c(10.0),
                    amplitude_um: c(5.0),
                    freq_hz: c(100.0),
                    phase_turns: c(0.0),
                },
            )
            .ok()?;
        Some(ctl)
    }

    /// Runs every row; SysTick is left free-running (no interrupt).
    pub fn run(syst: &mut SYST) -> Table {
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();

        const CAL: u32 = 100_000;
        let t0 = SYST::get_current();
        known_loop(CAL);
        let cal_ticks = ticks(t0, SYST::get_current()).max(1);
        let instr_per_tick_x1000 = ((2 * CAL as u64 * 1000) / cal_ticks as u64) as u32;

        // ADC codes of a closed-loop run, replayed identically to every timed run.
        let mut codes = [0i32; BENCH_STEPS];
        let mut overhead_ticks = 0;
        {
            let t0 = SYST::get_current();
            for c in codes.iter() {
                black_box(black_box(*c));
            }
            overhead_ticks = overhead_ticks.max(ticks(t0, SYST::get_current()));
        }

        let mut rows = [Row::default(); ROWS];
        let mut slot = rows.iter_mut();
        for law in LAWS {
            for ff in FFS {
                let Some(row) = slot.next() else { break };
                row.law = law;
                row.ff = ff;
                if !selected(law, ff) {
                    row.unsupported = true;
                    continue;
                }
                let Some(mut ctl) = configured(law, ff) else {
                    row.unsupported = true;
                    continue;
                };
                let mut stage = SimStage::new(SAMPLE_HZ as f32);
                let mut dac = 0;
                for c in codes.iter_mut() {
                    *c = stage.step(dac);
                    [dac, ..] = ctl.lp.step([*c; AXES]);
                }
                // Same codes, same initial state: the timed run repeats that trajectory.
                let Some(mut ctl) = configured(law, ff) else {
                    continue;
                };
                let mut worst = 0;
                for c in codes.iter().take(50) {
                    let t = SYST::get_current();
                    black_box(ctl.lp.step(black_box([*c; AXES])));
                    worst = worst.max(ticks(t, SYST::get_current()));
                }
                let Some(mut ctl) = configured(law, ff) else {
                    continue;
                };
                mark(1);
                let t0 = SYST::get_current();
                for c in codes.iter() {
                    black_box(ctl.lp.step(black_box([*c; AXES])));
                }
                let dt = ticks(t0, SYST::get_current()).saturating_sub(overhead_ticks);
                mark(2);
                row.instr_x100 =
                    ((dt as u64 * instr_per_tick_x1000 as u64) / (10 * BENCH_STEPS as u64)) as u32;
                row.max_instr = ((worst as u64 * instr_per_tick_x1000 as u64) / 1000) as u32;
            }
        }
        // The driver path alone, on the codes of the last row.
        let (mut adc, mut dac) = super::chips::drivers();
        let (adc, dac) = (black_box(&mut adc), black_box(&mut dac));
        let t0 = SYST::get_current();
        for c in codes.iter() {
            super::chips::INPUT_CODE.store(*c, core::sync::atomic::Ordering::Relaxed);
            adc.start_conversion().ok();
            let code = adc.read().unwrap_or(i32::MIN);
            dac.set_code(black_box(code.max(0))).ok();
        }
        let dt = ticks(t0, SYST::get_current()).saturating_sub(overhead_ticks);
        let drivers_x100 =
            ((dt as u64 * instr_per_tick_x1000 as u64) / (10 * BENCH_STEPS as u64)) as u32;
        Table {
            rows,
            instr_per_tick_x1000,
            overhead_ticks,
            drivers_x100,
        }
    }

    /// The table as text lines (UART) and, with `log`, defmt (semihosting stops the core,
    /// so not while the loop runs).
    pub fn print(t: &Table, log: bool) {
        let mut r = Reply::<160>::new();
        r.push_str("bench: instructions per control step (ADC code -> DAC code), ");
        r.push_usize(BENCH_STEPS);
        r.push_str(" steps, QEMU -icount shift=0, ");
        r.push_fixed(t.instr_per_tick_x1000, 3);
        r.push_str(" instr/SysTick tick, loop overhead ");
        r.push_u32(t.overhead_ticks);
        r.push_str(" ticks");
        uart::line(r.as_str());
        r.clear();
        r.push_str("bench: the rows count the pipeline step only; SPI driver path per sample (Ad4000 start+read, Ad5791 set_code, mock chips included): ");
        r.push_fixed(t.drivers_x100, 2);
        r.push_str(" instr");
        uart::line(r.as_str());
        uart::line("mode               feedforward        instr/step  first-50-max");
        for row in &t.rows {
            r.clear();
            r.push_padded(row.law, 19);
            r.push_padded(row.ff, 19);
            if row.unsupported {
                r.push_right("n/a", 10);
                uart::line(r.as_str());
                continue;
            }
            let mut n = Reply::<16>::new();
            n.push_fixed(row.instr_x100, 2);
            r.push_right(n.as_str(), 10);
            n.clear();
            n.push_u32(row.max_instr);
            r.push_str("  ");
            r.push_right(n.as_str(), 8);
            uart::line(r.as_str());
            if !log {
                continue;
            }
            defmt::info!(
                "bench {=str} + {=str}: {=u32}.{=u32:02} instructions/step",
                row.law,
                row.ff,
                row.instr_x100 / 100,
                row.instr_x100 % 100
            );
        }
    }
}

#[rtic::app(device = crate::board_qemu::pac, peripherals = false)]
mod app {
    use super::{bench, uart, Io, EXIT_LINE, PERIODS_MAX, PERIODS_MIN, SAMPLE_HZ, SYSTICK_HZ};
    use crate::control::{c, stream_frames, Ctl};
    use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
    use piezo_core::command::{self as cmd, Command, LineBuffer, RecCmd};

    #[shared]
    struct Shared {
        ctl: Ctl,
        periods: u32,
    }

    #[local]
    struct Local {
        io: Io,
        line: LineBuffer,
        table: bench::Table,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut syst = cx.core.SYST;
        uart::init();
        defmt::info!("qemu board: bench");
        let table = bench::run(&mut syst);
        bench::print(&table, true);
        if option_env!("PIEZO_BENCH_ONLY").is_some() {
            semihosting::process::exit(0);
        }

        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(SYSTICK_HZ / SAMPLE_HZ - 1);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        defmt::info!("qemu board: control loop at {=u32} Hz", SAMPLE_HZ);
        uart::line("ready");
        let mut ctl = Ctl::new(c(SAMPLE_HZ as f64));
        for axis in 0..crate::control::AXES {
            ctl.lp
                .p
                .set_wave(axis, piezo_core::pipeline::Wave::Hold { y_um: c(10.0) })
                .ok();
        }
        (
            Shared { ctl, periods: 0 },
            Local {
                io: Io::new(),
                line: LineBuffer::new(),
                table,
            },
        )
    }

    /// The control period. SysTick ticks stand in for cycles (x40 = instructions with
    /// `-icount shift=0`). The stage moves under the voltage of the DAC's output, the ADC
    /// driver samples and reads it, the DAC driver writes and loads the new code (every
    /// axis).
    #[task(binds = SysTick, priority = 2, shared = [ctl, periods], local = [io])]
    fn sample(cx: sample::Context) {
        let t0 = SYST::get_current();
        let io = cx.local.io;
        let code = io.read();
        (cx.shared.ctl, cx.shared.periods).lock(|ctl, periods| {
            let t1 = SYST::get_current();
            let dac_code = ctl.lp.step(code);
            let t2 = SYST::get_current();
            for (axis, held) in io.write(dac_code).into_iter().enumerate() {
                if let Some(held) = held {
                    ctl.lp.dac_write_failed(axis, held);
                }
            }
            ctl.record(code, dac_code);
            let overrun = SCB::is_pendst_pending();
            let t = &mut ctl.timing;
            t.step.record(elapsed(t1, t2));
            t.isr.record(elapsed(t0, SYST::get_current()));
            if overrun {
                t.overruns = t.overruns.wrapping_add(1);
            }
            *periods = periods.wrapping_add(1);
        });
    }

    /// Ticks between two readings of SysTick counting down within one period (a reload
    /// in between is undone).
    fn elapsed(start: u32, end: u32) -> u32 {
        const PERIOD: u32 = SYSTICK_HZ / SAMPLE_HZ;
        let d = start.wrapping_sub(end);
        if d > PERIOD {
            d.wrapping_add(PERIOD)
        } else {
            d
        }
    }

    #[idle(shared = [ctl, periods], local = [line, table])]
    fn idle(mut cx: idle::Context) -> ! {
        let mut answered = 0u32;
        let mut exit = false;
        loop {
            while let Some(byte) = uart::try_read() {
                let Some(line) = cx.local.line.push(byte) else {
                    continue;
                };
                if line == Ok(EXIT_LINE) {
                    exit = true;
                    continue;
                }
                let mut reply = cmd::Reply::<{ crate::control::REPLY_LEN }>::new();
                match line.and_then(cmd::parse) {
                    Ok(Command::Empty) => continue,
                    Ok(Command::Bench) => {
                        bench::print(cx.local.table, false);
                        reply.push_str("ok bench ");
                        reply.push_usize(bench::ROWS);
                    }
                    Ok(Command::Rec(RecCmd::Read { start, count })) => {
                        let ctl = &mut cx.shared.ctl;
                        stream_frames(
                            start,
                            count,
                            |i| ctl.lock(|c| c.rec.frame(i).copied()),
                            uart::line,
                        );
                        answered += 1;
                        continue;
                    }
                    Ok(c) => cx.shared.ctl.lock(|ctl| ctl.execute(c, &mut reply)),
                    Err(e) => reply.push_error(e),
                }
                uart::line(reply.as_str());
                answered += 1;
            }
            let periods = cx.shared.periods.lock(|p| *p);
            if exit && periods >= PERIODS_MIN {
                finish(&mut cx.shared.ctl, periods, answered, 0);
            }
            if periods >= PERIODS_MAX && answered == 0 {
                uart::line("error: no command received");
                finish(&mut cx.shared.ctl, periods, answered, 1);
            }
        }
    }

    fn finish(ctl: &mut impl rtic::Mutex<T = Ctl>, periods: u32, answered: u32, code: i32) -> ! {
        let t = ctl.lock(|c| c.timing);
        let mut r = cmd::Reply::<160>::new();
        r.push_str("done periods ");
        r.push_u32(periods);
        r.push_str(" commands ");
        r.push_u32(answered);
        r.push_str(" step_ticks ");
        r.push_u32(t.step.min);
        r.push_str(" ");
        r.push_u32(t.step.max);
        r.push_str(" isr_ticks ");
        r.push_u32(t.isr.min);
        r.push_str(" ");
        r.push_u32(t.isr.max);
        r.push_str(" overruns ");
        r.push_u32(t.overruns);
        uart::line(r.as_str());
        defmt::info!(
            "done: {=u32} periods, {=u32} commands, step ticks min {=u32} max {=u32}, overruns {=u32}",
            periods,
            answered,
            t.step.min,
            t.step.max,
            t.overruns
        );
        semihosting::process::exit(code)
    }
}

/// A panic ends the QEMU run with a failure status.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    uart::line("panic");
    semihosting::process::exit(101)
}
