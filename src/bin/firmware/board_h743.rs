//! Nucleo-H743ZI2 (STM32H743ZI): everything board-specific lives here.
//!
//! Converters, on-chip (default):
//! * TIM2 overflows at the sample rate; its update event (TRGO) starts an ADC1 conversion in
//!   hardware, so the sampling instant does not jitter with interrupt latency.
//! * The ADC1 end-of-conversion interrupt is the highest-priority task: read the sample, run
//!   the step, write the DAC (PA4, DAC1 channel 1). Analog input: PA3 (ADC12_INP15, CN9
//!   pin 1 "A0" on the Nucleo-144).
//! * Feature `xy` (two axes): ADC2 converts the y input on the same TIM2 TRGO edge (PC0,
//!   ADC123_INP10, CN9 pin 3 "A1"); the ADC1 interrupt reads both (ADC2, started on the same
//!   edge with the same timing, is waited for a bounded number of polls; late counts as an
//!   overrun and gives a code outside the sensor window, the safe state). The y output is
//!   DAC1 channel 2 (PA5, CN7 pin 10 "D13"; the green LED LD1 is on PB0, not PA5, on the
//!   Nucleo-144).
//!
//! Converters, external SPI pair (feature `spi-converters`), through the drivers of
//! [`piezo_core::drivers`] (the ones hal-sim runs on its mock chips):
//! * AD4020 position ADC on SPI1 (SCK PA5, SDO -> MISO PA6, SDI <- MOSI PB5). Its CNV input
//!   is driven by TIM2 channel 1 (PA0, PWM mode 1): high for the first 1/20 of every sample
//!   period (500 ns at 100 kHz, > t_CONV 320 ns), so the conversion starts in hardware at
//!   the period boundary. The CC1 interrupt (CNV falls: the conversion is done) is the
//!   control task: `Ad4000::read`, the step, `Ad5791::set_code`.
//! * AD5791 DAC on SPI4 (SCK PE2, SDO -> MISO PE5, SDIN <- MOSI PE6), SYNC on PE4, LDAC on
//!   PE3.
//! * The SPI pair drives one axis; `xy` with `spi-converters` does not compile (a second
//!   AD4020/AD5791 pair needs its own buses or chip selects, not wired here).
//! * stm32h7xx-hal 0.16 implements embedded-hal 0.2 SPI; [`spi`] adapts it to the
//!   embedded-hal 1.0 `SpiDevice` the drivers take (byte-wise full-duplex exchanges with a
//!   bounded wait, chip select around each transaction).
//!
//! Common:
//! * USART3 (ST-LINK virtual COM port, PD8/PD9, 115200 Bd) carries the command protocol;
//!   its receive interrupt runs at priority 1. Replies are written without `core::fmt`.
//! * Telemetry (timing, overruns) goes over defmt-RTT once per second from `idle`: defmt
//!   logs from thread mode only (init, then idle), never from an interrupt handler, so its
//!   logger lock is never contended and no handler reaches its reentrancy panic. Timing is
//!   kept by the DWT cycle counter: no monotonic timer, no async task, no dispatcher.

use crate::control::AXES;
pub use crate::control::SAMPLE_HZ;

#[cfg(all(feature = "spi-converters", feature = "xy"))]
compile_error!(
    "feature `xy` (two axes) needs the on-chip converters: the SPI pair (`spi-converters`) drives one axis"
);

/// Core clock (Hz): DWT cycle counts are in these cycles.
pub const SYSCLK_HZ: u32 = 400_000_000;
/// Independent watchdog timeout (ms): 1000 control periods without a healthy one.
pub const WATCHDOG_MS: u32 = 10;

/// embedded-hal 1.0 devices over stm32h7xx-hal's embedded-hal 0.2 SPI and GPIO.
#[cfg_attr(not(feature = "spi-converters"), allow(dead_code))]
pub mod spi {
    use core::convert::Infallible;
    use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
    use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
    use stm32h7xx_hal::hal as hal02;
    use stm32h7xx_hal::nb;

    /// Polls of a status flag before a byte exchange is given up (a byte takes ~130 polls
    /// at 25 MHz SCK and 400 MHz core clock).
    const MAX_POLLS: u32 = 10_000;

    /// A failed SPI exchange.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum SpiError {
        /// The peripheral reported an error (overrun, mode fault, ...).
        Bus,
        /// A status flag did not come within [`MAX_POLLS`] polls.
        Timeout,
    }

    impl embedded_hal::spi::Error for SpiError {
        fn kind(&self) -> ErrorKind {
            ErrorKind::Other
        }
    }

    /// An embedded-hal 1.0 `SpiDevice`: an embedded-hal 0.2 full-duplex bus plus a chip
    /// select held low for the whole transaction.
    pub struct SpiDev<BUS, CS> {
        bus: BUS,
        cs: CS,
    }

    impl<BUS, CS: OutputPin> SpiDev<BUS, CS> {
        pub fn new(bus: BUS, mut cs: CS) -> Self {
            cs.set_high().ok();
            Self { bus, cs }
        }
    }

    impl<BUS: hal02::spi::FullDuplex<u8>, CS> SpiDev<BUS, CS> {
        /// One byte out, one byte in; bounded.
        #[inline]
        fn exchange(&mut self, out: u8) -> Result<u8, SpiError> {
            poll(|| self.bus.send(out))?;
            poll(|| self.bus.read())
        }
    }

    #[inline]
    fn poll<T, E>(mut f: impl FnMut() -> nb::Result<T, E>) -> Result<T, SpiError> {
        for _ in 0..MAX_POLLS {
            match f() {
                Ok(v) => return Ok(v),
                Err(nb::Error::WouldBlock) => {}
                Err(nb::Error::Other(_)) => return Err(SpiError::Bus),
            }
        }
        Err(SpiError::Timeout)
    }

    impl<BUS, CS> ErrorType for SpiDev<BUS, CS> {
        type Error = SpiError;
    }

    impl<BUS: hal02::spi::FullDuplex<u8>, CS: OutputPin> SpiDevice for SpiDev<BUS, CS> {
        fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), SpiError> {
            self.cs.set_low().ok();
            let mut result = Ok(());
            for op in ops.iter_mut() {
                result = match op {
                    Operation::Read(buf) => buf.iter_mut().try_for_each(|b| {
                        *b = self.exchange(0)?;
                        Ok(())
                    }),
                    Operation::Write(buf) => {
                        buf.iter().try_for_each(|&b| self.exchange(b).map(|_| ()))
                    }
                    Operation::Transfer(read, write) => {
                        // Words beyond `write` are zeros; words beyond `read` are dropped.
                        let n = read.len().max(write.len());
                        (0..n).try_for_each(|i| {
                            let v = self.exchange(write.get(i).copied().unwrap_or(0))?;
                            if let Some(r) = read.get_mut(i) {
                                *r = v;
                            }
                            Ok(())
                        })
                    }
                    Operation::TransferInPlace(buf) => buf.iter_mut().try_for_each(|b| {
                        *b = self.exchange(*b)?;
                        Ok(())
                    }),
                    Operation::DelayNs(ns) => {
                        cortex_m::asm::delay(
                            ns.saturating_mul(super::SYSCLK_HZ / 1_000_000) / 1000,
                        );
                        Ok(())
                    }
                };
                if result.is_err() {
                    break;
                }
            }
            self.cs.set_high().ok();
            result
        }
    }

    /// An embedded-hal 0.2 GPIO output as an embedded-hal 1.0 `OutputPin`.
    pub struct Gpio<P>(pub P);

    impl<P> PinErrorType for Gpio<P> {
        type Error = Infallible;
    }

    impl<P: hal02::digital::v2::OutputPin> OutputPin for Gpio<P> {
        fn set_low(&mut self) -> Result<(), Infallible> {
            self.0.set_low().ok();
            Ok(())
        }
        fn set_high(&mut self) -> Result<(), Infallible> {
            self.0.set_high().ok();
            Ok(())
        }
    }

    /// A pin the hardware drives, not the driver: the AD4020's CNV (TIM2 channel 1), and
    /// its chip select (CNV doubles as CS in the 3-wire mode). Setting it does nothing.
    pub struct HardwarePin;

    impl PinErrorType for HardwarePin {
        type Error = Infallible;
    }

    impl OutputPin for HardwarePin {
        fn set_low(&mut self) -> Result<(), Infallible> {
            Ok(())
        }
        fn set_high(&mut self) -> Result<(), Infallible> {
            Ok(())
        }
    }
}

/// What the control task owns besides the control state.
pub struct Hw {
    pub io: io::Io,
    /// Fed only by a control period that met its deadline.
    pub watchdog: stm32h7xx_hal::independent_watchdog::IndependentWatchdog,
    /// The deadline: core cycles per sample period.
    pub period_cycles: u32,
}

/// The converters the control task touches, for the selected variant.
#[cfg(not(feature = "spi-converters"))]
pub mod io {
    use super::AXES;
    use stm32h7xx_hal::{adc, pac, timer::Timer, traits::DacOut};

    pub type DacChannel = stm32h7xx_hal::dac::C1<pac::DAC, stm32h7xx_hal::dac::Enabled>;
    #[cfg(feature = "xy")]
    pub type DacChannel2 = stm32h7xx_hal::dac::C2<pac::DAC, stm32h7xx_hal::dac::Enabled>;

    /// Polls of ADC2's end of conversion after ADC1's (same trigger, same timing: it is
    /// normally done already).
    #[cfg(feature = "xy")]
    const ADC2_POLLS: u32 = 64;

    /// On-chip ADC1 (16 bit, started by TIM2 TRGO) and DAC1 channel 1 (12 bit); with `xy`
    /// also ADC2 (same trigger) and DAC1 channel 2.
    pub struct Io {
        pub adc: adc::Adc<pac::ADC1, adc::Enabled>,
        pub dac: DacChannel,
        #[cfg(feature = "xy")]
        pub adc2: adc::Adc<pac::ADC2, adc::Enabled>,
        #[cfg(feature = "xy")]
        pub dac2: DacChannel2,
        pub timer: Timer<pac::TIM2>,
    }

    /// The conversion result of `regs`, and whether one was overwritten (OVR).
    #[inline(always)]
    fn take(regs: &pac::adc1::RegisterBlock) -> (i32, bool) {
        // Reading DR clears EOC. OVR means a conversion was overwritten.
        let overrun = regs.isr.read().ovr().bit_is_set();
        if overrun {
            regs.isr.write(|w| w.ovr().set_bit());
        }
        (regs.dr.read().bits() as i32, overrun)
    }

    impl Io {
        /// This period's ADC codes, and whether a conversion was lost (a missed deadline).
        #[inline(always)]
        pub fn sample(&mut self) -> ([i32; AXES], bool) {
            let (x, overrun) = take(self.adc.inner());
            #[cfg(not(feature = "xy"))]
            return ([x], overrun);
            #[cfg(feature = "xy")]
            {
                let regs: &pac::adc1::RegisterBlock = self.adc2.inner();
                let mut ready = false;
                for _ in 0..ADC2_POLLS {
                    if regs.isr.read().eoc().bit_is_set() {
                        ready = true;
                        break;
                    }
                }
                let (y, overrun2) = take(regs);
                // Late: an old sample would be stale; outside the sensor window instead.
                let y = if ready { y } else { i32::MIN };
                ([x, y], overrun || overrun2 || !ready)
            }
        }

        /// Writes the DACs; per axis, the code a DAC still holds after a failed write
        /// (never, on-chip).
        #[inline(always)]
        pub fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
            #[cfg(not(feature = "xy"))]
            let [x] = codes;
            #[cfg(feature = "xy")]
            let [x, y] = codes;
            self.dac.set_value(x as u16);
            #[cfg(feature = "xy")]
            self.dac2.set_value(y as u16);
            [None; AXES]
        }
    }
}

/// The converters the control task touches, for the selected variant.
#[cfg(feature = "spi-converters")]
pub mod io {
    use super::spi::{Gpio, HardwarePin, SpiDev};
    use crate::control::{ActuatorDac, PositionAdc};
    use stm32h7xx_hal::gpio::{Output, PushPull, PE3, PE4};
    use stm32h7xx_hal::{pac, spi::Enabled, spi::Spi, timer::Timer};

    pub type AdcBus = SpiDev<Spi<pac::SPI1, Enabled, u8>, HardwarePin>;
    pub type DacBus = SpiDev<Spi<pac::SPI4, Enabled, u8>, Gpio<PE4<Output<PushPull>>>>;
    pub type Adc = PositionAdc<AdcBus, HardwarePin>;
    pub type Dac = ActuatorDac<DacBus, Gpio<PE3<Output<PushPull>>>>;

    use super::AXES;

    /// AD4020 (CNV from TIM2 CH1) and AD5791 through the core's drivers.
    pub struct Io {
        pub adc: Adc,
        pub dac: Dac,
        pub timer: Timer<pac::TIM2>,
        /// The code the DAC holds (the last write that succeeded).
        pub held: i32,
    }

    impl Io {
        /// This period's ADC code (a failed read gives a code outside every sensor window:
        /// the pipeline's range check takes the safe state), and whether a period was lost.
        #[inline(always)]
        pub fn sample(&mut self) -> ([i32; AXES], bool) {
            let tim = self.timer.inner();
            // CC1OF: a CNV edge came while the previous one was still pending.
            let overrun = tim.sr.read().cc1of().bit_is_set();
            tim.sr
                .modify(|_, w| w.cc1if().clear_bit().cc1of().clear_bit());
            ([self.adc.read().unwrap_or(i32::MIN); AXES], overrun)
        }

        /// Writes and loads the DAC; on failure returns the code it still holds.
        #[inline(always)]
        pub fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
            let [code] = codes;
            match self.dac.set_code(code) {
                Ok(()) => {
                    self.held = code;
                    [None]
                }
                Err(_) => [Some(self.held)],
            }
        }
    }
}

#[rtic::app(device = stm32h7xx_hal::pac, peripherals = true)]
mod app {
    use super::io::Io;
    use super::{Hw, SAMPLE_HZ, SYSCLK_HZ, WATCHDOG_MS};
    use crate::control::{c, stream_frames, Ctl};
    use cortex_m::peripheral::DWT;
    use piezo_core::command::{self as cmd, Command, LineBuffer, RecCmd};
    use stm32h7xx_hal::{
        delay::Delay, independent_watchdog::IndependentWatchdog, pac, prelude::*, serial,
    };

    #[shared]
    struct Shared {
        ctl: Ctl,
    }

    #[local]
    struct Local {
        // The control task's hardware (one field per converter variant: RTIC names each
        // local resource once across the variants).
        #[cfg(not(feature = "spi-converters"))]
        hw_adc: Hw,
        #[cfg(feature = "spi-converters")]
        hw_spi: Hw,
        rx: serial::Rx<pac::USART3>,
        tx: serial::Tx<pac::USART3>,
        line: LineBuffer,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cp = cx.core;
        let dp = cx.device;

        let pwrcfg = dp.PWR.constrain().freeze();
        // PLL2P: ADC kernel clock; PLL1Q: SPI1 kernel clock (SPI4 runs from PCLK2).
        let mut ccdr = dp
            .RCC
            .constrain()
            .sys_ck(SYSCLK_HZ.Hz())
            .pll1_q_ck(100.MHz())
            .pll2_p_ck(72.MHz())
            .freeze(pwrcfg, &dp.SYSCFG);
        ccdr.peripheral
            .kernel_adc_clk_mux(stm32h7xx_hal::rcc::rec::AdcClkSel::Pll2P);

        cp.DCB.enable_trace();
        DWT::unlock();
        cp.DWT.enable_cycle_counter();

        #[allow(unused_mut)] // only the on-chip converters use it
        let mut delay = Delay::new(cp.SYST, ccdr.clocks);
        let gpioa = dp.GPIOA.split(ccdr.peripheral.GPIOA);
        let gpiod = dp.GPIOD.split(ccdr.peripheral.GPIOD);
        // The converters, TIM2 configured but not running yet.
        #[cfg(not(feature = "spi-converters"))]
        let io = {
            use stm32h7xx_hal::adc;
            // DAC1 channel 1 on PA4 (xy: channel 2 on PA5).
            #[cfg(not(feature = "xy"))]
            let dac = dp
                .DAC
                .dac(gpioa.pa4, ccdr.peripheral.DAC12)
                .calibrate_buffer(&mut delay)
                .enable();
            #[cfg(feature = "xy")]
            let (dac, dac2) = {
                let (c1, c2) = dp.DAC.dac((gpioa.pa4, gpioa.pa5), ccdr.peripheral.DAC12);
                (
                    c1.calibrate_buffer(&mut delay).enable(),
                    c2.calibrate_buffer(&mut delay).enable(),
                )
            };
            // ADC1 (xy: and ADC2), 16 bit, triggered by TIM2 TRGO.
            #[cfg(not(feature = "xy"))]
            let mut adc = adc::Adc::adc1(
                dp.ADC1,
                36.MHz(),
                &mut delay,
                ccdr.peripheral.ADC12,
                &ccdr.clocks,
            )
            .enable();
            #[cfg(feature = "xy")]
            let (mut adc, mut adc2) = {
                let (a1, a2) = adc::adc12(
                    dp.ADC1,
                    dp.ADC2,
                    36.MHz(),
                    &mut delay,
                    ccdr.peripheral.ADC12,
                    &ccdr.clocks,
                );
                (a1.enable(), a2.enable())
            };
            adc.set_resolution(adc::Resolution::SixteenBit);
            adc.set_sample_time(adc::AdcSampleTime::T_8);
            configure_adc_trigger(adc.inner(), true);
            let mut ain = gpioa.pa3.into_analog();
            adc.start_conversion(&mut ain);
            #[cfg(feature = "xy")]
            {
                let gpioc = dp.GPIOC.split(ccdr.peripheral.GPIOC);
                adc2.set_resolution(adc::Resolution::SixteenBit);
                adc2.set_sample_time(adc::AdcSampleTime::T_8);
                // Its result is read by ADC1's interrupt.
                configure_adc_trigger(adc2.inner(), false);
                let mut ain2 = gpioc.pc0.into_analog();
                adc2.start_conversion(&mut ain2);
            }
            let mut timer = dp
                .TIM2
                .timer(SAMPLE_HZ.Hz(), ccdr.peripheral.TIM2, &ccdr.clocks);
            timer.pause();
            timer.inner_mut().cr2.modify(|_, w| w.mms().update());
            Io {
                adc,
                dac,
                #[cfg(feature = "xy")]
                adc2,
                #[cfg(feature = "xy")]
                dac2,
                timer,
            }
        };
        #[cfg(feature = "spi-converters")]
        let io = {
            use super::io::{Adc, Dac};
            use super::spi::{Gpio, HardwarePin, SpiDev};
            use crate::control::{ADC_CONFIG, DAC_CONFIG};
            use stm32h7xx_hal::spi;
            let gpiob = dp.GPIOB.split(ccdr.peripheral.GPIOB);
            let gpioe = dp.GPIOE.split(ccdr.peripheral.GPIOE);
            let adc_bus: spi::Spi<_, _, u8> = dp.SPI1.spi(
                (
                    gpioa.pa5.into_alternate::<5>(),
                    gpioa.pa6.into_alternate::<5>(),
                    gpiob.pb5.into_alternate::<5>(),
                ),
                spi::MODE_0,
                25.MHz(),
                ccdr.peripheral.SPI1,
                &ccdr.clocks,
            );
            let dac_bus: spi::Spi<_, _, u8> = dp.SPI4.spi(
                (
                    gpioe.pe2.into_alternate::<5>(),
                    gpioe.pe5.into_alternate::<5>(),
                    gpioe.pe6.into_alternate::<5>(),
                ),
                spi::MODE_1,
                25.MHz(),
                ccdr.peripheral.SPI4,
                &ccdr.clocks,
            );
            // CNV stays low (TIM2 CH1 output disabled) while the registers are set up.
            let _cnv = gpioa.pa0.into_alternate::<1>();
            let mut adc = Adc::new(SpiDev::new(adc_bus, HardwarePin), HardwarePin, ADC_CONFIG)
                .unwrap_or_else(|_| panic!("AD4020 driver"));
            adc.init()
                .unwrap_or_else(|_| panic!("AD4020 does not answer"));
            let sync = Gpio(gpioe.pe4.into_push_pull_output());
            let ldac = Gpio(gpioe.pe3.into_push_pull_output());
            let mut dac = Dac::new(SpiDev::new(dac_bus, sync), ldac, DAC_CONFIG)
                .unwrap_or_else(|_| panic!("AD5791 driver"));
            dac.init(0)
                .unwrap_or_else(|_| panic!("AD5791 does not answer"));
            // TIM2: CH1 in PWM mode 1 is CNV, high for 1/20 of the period from the update
            // event on; its compare interrupt (CNV falls) runs the control task.
            let mut timer = dp
                .TIM2
                .timer(SAMPLE_HZ.Hz(), ccdr.peripheral.TIM2, &ccdr.clocks);
            timer.pause();
            let tim = timer.inner_mut();
            let arr = tim.arr.read().arr().bits();
            tim.ccr1().write(|w| w.ccr().bits(arr / 20 + 1));
            tim.ccmr1_output()
                .modify(|_, w| w.oc1m().pwm_mode1().oc1pe().set_bit());
            tim.ccer.modify(|_, w| w.cc1e().set_bit());
            tim.dier.modify(|_, w| w.cc1ie().set_bit());
            Io {
                adc,
                dac,
                timer,
                held: 0,
            }
        };

        let serial = dp
            .USART3
            .serial(
                (gpiod.pd8.into_alternate(), gpiod.pd9.into_alternate()),
                115_200.bps(),
                ccdr.peripheral.USART3,
                &ccdr.clocks,
            )
            .unwrap_or_else(|_| panic!("USART3 setup"));
        let (tx, mut rx) = serial.split();
        rx.listen();

        let _ = delay.free();

        // Independent watchdog (LSI clock, survives a main-clock failure): only a control
        // period that met its deadline feeds it, so a stalled or overrunning loop resets
        // the MCU, whose DAC then comes up at its safe code.
        let mut watchdog = IndependentWatchdog::new(dp.IWDG);
        watchdog.start(stm32h7xx_hal::time::MilliSeconds::from_ticks(WATCHDOG_MS));

        // TIM2 last: from here on samples arrive.
        let mut io = io;
        io.timer.resume();
        let hw = Hw {
            io,
            watchdog,
            period_cycles: SYSCLK_HZ / SAMPLE_HZ,
        };

        defmt::info!("firmware up: {} Hz sample rate", SAMPLE_HZ);
        (
            Shared {
                ctl: Ctl::new(c(SAMPLE_HZ as f64)),
            },
            Local {
                #[cfg(not(feature = "spi-converters"))]
                hw_adc: hw,
                #[cfg(feature = "spi-converters")]
                hw_spi: hw,
                rx,
                tx,
                line: LineBuffer::new(),
            },
        )
    }

    /// ADC1 (or ADC2): external trigger TIM2_TRGO (EXTSEL 11, RM0433 table 205), rising
    /// edge, and the end-of-conversion interrupt if `eoc_interrupt`.
    #[cfg(not(feature = "spi-converters"))]
    fn configure_adc_trigger(adc: &pac::adc1::RegisterBlock, eoc_interrupt: bool) {
        // SAFETY: EXTSEL is a 5-bit field; 11 selects tim2_trgo.
        #[allow(unsafe_code)]
        adc.cfgr
            .modify(|_, w| unsafe { w.extsel().bits(11) }.exten().rising_edge());
        adc.ier
            .modify(|_, w| w.eocie().bit(eoc_interrupt).ovrie().clear_bit());
    }

    /// The control period, on-chip converters: ADC1 end of conversion. Highest priority.
    #[cfg(not(feature = "spi-converters"))]
    #[task(binds = ADC1_2, priority = 3, shared = [ctl], local = [hw_adc])]
    fn sample_adc(mut cx: sample_adc::Context) {
        control_period(cx.local.hw_adc, &mut cx.shared.ctl);
    }

    /// The control period, SPI converters: TIM2 CC1 (CNV fell, the conversion is done).
    #[cfg(feature = "spi-converters")]
    #[task(binds = TIM2, priority = 3, shared = [ctl], local = [hw_spi])]
    fn sample_tim(mut cx: sample_tim::Context) {
        control_period(cx.local.hw_spi, &mut cx.shared.ctl);
    }

    /// Sample in, step, DAC out, timing; the watchdog is fed only when the deadline held.
    #[inline(always)]
    fn control_period(hw: &mut Hw, ctl: &mut impl rtic::Mutex<T = Ctl>) {
        let Hw {
            io,
            watchdog,
            period_cycles: period,
        } = hw;
        let period = *period;
        let t0 = DWT::cycle_count();
        let (code, overrun) = io.sample();
        ctl.lock(|ctl| {
            let t1 = DWT::cycle_count();
            let dac_code = ctl.lp.step(code);
            let t2 = DWT::cycle_count();
            for (axis, held) in io.write(dac_code).into_iter().enumerate() {
                if let Some(held) = held {
                    ctl.lp.dac_write_failed(axis, held);
                }
            }
            ctl.record(code, dac_code);
            let isr = DWT::cycle_count().wrapping_sub(t0);
            let t = &mut ctl.timing;
            t.step.record(t2.wrapping_sub(t1));
            t.isr.record(isr);
            if overrun || isr > period {
                t.overruns = t.overruns.wrapping_add(1);
            } else {
                watchdog.feed();
            }
        });
    }

    /// Command lines from the serial port (priority 1; the control task preempts it).
    #[task(binds = USART3, priority = 1, shared = [ctl], local = [rx, tx, line])]
    fn serial_rx(mut cx: serial_rx::Context) {
        use stm32h7xx_hal::hal::serial::Read;
        let tx = cx.local.tx;
        while let Ok(byte) = cx.local.rx.read() {
            let Some(line) = cx.local.line.push(byte) else {
                continue;
            };
            let mut reply = cmd::Reply::<{ crate::control::REPLY_LEN }>::new();
            match line.and_then(cmd::parse) {
                Ok(Command::Empty) => continue,
                Ok(Command::Rec(RecCmd::Read { start, count })) => {
                    let ctl = &mut cx.shared.ctl;
                    stream_frames(
                        start,
                        count,
                        |i| ctl.lock(|c| c.rec.frame(i).copied()),
                        |l| send(tx, l),
                    );
                    continue;
                }
                Ok(c) => cx.shared.ctl.lock(|ctl| ctl.execute(c, &mut reply)),
                Err(e) => reply.push_error(e),
            }
            send(tx, reply.as_str());
        }
    }

    /// One reply line, blocking (low priority; 115200 Bd: the holding register always
    /// drains, the control task preempts the wait).
    fn send(tx: &mut serial::Tx<pac::USART3>, line: &str) {
        use stm32h7xx_hal::hal::serial::Write;
        for &b in line.as_bytes().iter().chain(b"\r\n") {
            while let Err(stm32h7xx_hal::nb::Error::WouldBlock) = tx.write(b) {}
        }
    }

    /// Timing and overruns over defmt, once per second (DWT cycle counter), from thread
    /// mode: the only context besides `init` that logs.
    #[idle(shared = [ctl])]
    fn idle(mut cx: idle::Context) -> ! {
        let mut last = DWT::cycle_count();
        loop {
            if DWT::cycle_count().wrapping_sub(last) < SYSCLK_HZ {
                continue;
            }
            last = last.wrapping_add(SYSCLK_HZ);
            let t = cx.shared.ctl.lock(|c| c.timing);
            defmt::info!(
                "step cycles min {} max {} last {} | isr min {} max {} last {} | samples {} overruns {}",
                t.step.min, t.step.max, t.step.last, t.isr.min, t.isr.max, t.isr.last,
                t.isr.count, t.overruns
            );
        }
    }
}
