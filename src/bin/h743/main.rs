//! Firmware for the Nucleo-H743ZI2 (STM32H743ZI, Cortex-M7F). The control period and the
//! command line are the library's ([`piezo_core::firmware`]); this board supplies the
//! hardware side: converters ([`onchip`] or [`spi_pair`]), the DWT cycle counter, the
//! watchdog and USART3.
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
//!   control task: `Ad4000::read`, the step, `Ad5791::write_code`.
//! * AD5791 DAC on SPI4 (SCK PE2, SDO -> MISO PE5, SDIN <- MOSI PE6), SYNC on PE4. Its LDAC
//!   is TIM2 channel 2 (PB3, PWM mode 2: low for the first 1/40 of every period): the code
//!   written in one period reaches the output at the next period's start, one period after
//!   its sample, whatever the step's length. (A GPIO while the DAC is configured at the
//!   safe code; PB3 is the ST-LINK's SWO, unused: telemetry is RTT.)
//! * The SPI pair drives one axis; `xy` with `spi-converters` does not compile (a second
//!   AD4020/AD5791 pair needs its own buses or chip selects, not wired here).
//! * stm32h7xx-hal 0.16 implements embedded-hal 0.2 SPI; [`spi`] adapts it to the
//!   embedded-hal 1.0 `SpiDevice` the drivers take (byte-wise full-duplex exchanges with a
//!   bounded wait, chip select around each transaction).
//!
//! Common:
//! * USART3 (ST-LINK virtual COM port, PD8/PD9, 115200 Bd) carries the command protocol;
//!   its receive interrupt runs at priority 1 and holds the control task's lock only for
//!   copies ([`piezo_core::firmware::CommandLine`]). Replies are written without `core::fmt`.
//! * Telemetry (timing, overruns) goes over defmt-RTT once per second from `idle`: defmt
//!   logs from thread mode only (init, then idle), never from an interrupt handler, so its
//!   logger is never contended; defmt-rtt runs without a critical section and never blocks
//!   (`drop-on-contention`, `disable-blocking-mode`), so logging masks no interrupt. Timing is
//!   kept by the DWT cycle counter: no monotonic timer, no async task, no dispatcher.
//!
//! Build and flash (probe-rs, `.cargo/config.toml`'s runner):
//! `cargo run --release --target thumbv7em-none-eabihf` (features `spi-converters`, `xy`).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(all(target_os = "none", not(target_abi = "eabihf")))]
compile_error!("the H743 is a Cortex-M7F: build it with --target thumbv7em-none-eabihf");

#[cfg(all(target_os = "none", feature = "spi-converters", feature = "xy"))]
compile_error!(
    "feature `xy` (two axes) needs the on-chip converters: the SPI pair (`spi-converters`) drives one axis"
);

#[cfg(all(target_os = "none", not(feature = "spi-converters")))]
mod onchip;
#[cfg(target_os = "none")]
mod safe;
#[cfg(target_os = "none")]
mod selftest;
#[cfg(target_os = "none")]
mod settings;
#[cfg(all(target_os = "none", feature = "spi-converters"))]
mod spi;
#[cfg(all(target_os = "none", feature = "spi-converters"))]
mod spi_pair;

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("h743: build with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use board::*;

#[cfg(target_os = "none")]
mod board {
    use cortex_m::peripheral::DWT;
    use piezo_core::command::{Error, Reply};
    use piezo_core::firmware::{self, Clock, Port, REPLY_LEN};
    use stm32h7xx_hal::{independent_watchdog::IndependentWatchdog, pac, serial};
    // The panic handler is the board's own (`safe`): the safe state first.
    use defmt_rtt as _;

    /// Core clock (Hz): DWT cycle counts are in these cycles.
    pub const SYSCLK_HZ: u32 = 400_000_000;
    /// Core cycles per control period besides the step (interrupt entry and exit, timing,
    /// recorder, converters): on-chip a few register accesses; the SPI pair clocks 2 x 24
    /// bits at 25 MHz (about 2 us) and waits out t_CONV in hardware.
    #[cfg(not(feature = "spi-converters"))]
    pub const OVERHEAD_CYCLES: u32 = 400;
    #[cfg(feature = "spi-converters")]
    pub const OVERHEAD_CYCLES: u32 = 1_200;
    /// Independent watchdog timeout (ms): 1000 control periods without a healthy one.
    pub const WATCHDOG_MS: u32 = 10;

    // ITCM is loaded in `__pre_init` (cortex-m-rt calls it first in the reset handler, before
    // .data and .bss): nothing can run from ITCM before it holds its code, not even a
    // `__aeabi_memcpy` (placed there for the control path) called by init or by the runtime.
    // Assembly: no stack, no statics, no calls. ITCM is on at reset on the H7
    // (CM7_ITCMCR.EN); it is set anyway, as stabilizer does. build.rs's `.itcm` section is
    // word aligned (its bounds `__sitcm`/`__eitcm`, its flash image `__siitcm`).
    #[allow(unsafe_code)]
    mod pre_init {
        core::arch::global_asm!(
            ".section .text.__pre_init,\"ax\",%progbits",
            ".global __pre_init",
            ".type __pre_init,%function",
            ".thumb_func",
            "__pre_init:",
            "    ldr r0, =0xE000EF90",
            "    ldr r1, [r0]",
            "    orr r1, r1, #1",
            "    str r1, [r0]",
            "    dsb",
            "    isb",
            "    ldr r0, =__sitcm",
            "    ldr r1, =__eitcm",
            "    ldr r2, =__siitcm",
            "1:",
            "    cmp r0, r1",
            "    bhs 2f",
            "    ldr r3, [r2], #4",
            "    str r3, [r0], #4",
            "    b 1b",
            "2:",
            "    dsb",
            "    isb",
            "    bx lr",
            ".ltorg",
        );
    }

    /// The converters of this build, and the control state over them.
    #[cfg(not(feature = "spi-converters"))]
    pub use super::onchip::Io;
    #[cfg(not(feature = "spi-converters"))]
    pub type Conv = firmware::OnChip;
    #[cfg(feature = "spi-converters")]
    pub use super::spi_pair::Io;
    #[cfg(feature = "spi-converters")]
    pub type Conv = firmware::SpiPair;
    pub type Ctl = firmware::Ctl<Conv>;
    use piezo_core::firmware::REC_CH;

    /// Recorder frames: all 512 KiB of the AXI SRAM (build.rs's `.axisram`), 32 768 frames,
    /// 328 ms at 100 kHz.
    pub const REC_FRAMES: usize = 512 * 1024 / (REC_CH * 4);

    // The recorder's storage in the AXI SRAM: [`REC_FRAMES`] frames of [`REC_CH`] values (512 KiB), in the
    // NOLOAD section `.axisram` (nothing copies or zeroes it at reset); zeroed here once.
    // `None` on a second call.
    piezo_core::recorder_storage!(".axisram", REC_FRAMES);

    /// What the control task owns besides the control state.
    pub struct Hw {
        pub io: Io,
        /// Fed only by a control period that met its deadline.
        pub watchdog: IndependentWatchdog,
        pub clock: Dwt,
    }

    /// The DWT cycle counter (core clock), and TIM2's counter for the time since the
    /// control interrupt's trigger.
    pub struct Dwt {
        /// The deadline: core cycles per sample period.
        pub period_cycles: u32,
        /// Core cycles per TIM2 tick (SYSCLK / TIM2's kernel clock).
        pub cycles_per_tick: u32,
        /// TIM2 ticks per period (ARR + 1).
        pub ticks: u32,
        /// TIM2's count at the trigger: 0 on-chip (the update event starts the ADC), CCR1
        /// with SPI converters (CNV falls, the compare interrupt runs the control task).
        pub trigger_count: u32,
    }

    /// The control task's interrupt: pending again means the next sample is due.
    #[cfg(not(feature = "spi-converters"))]
    pub const CONTROL_IRQ: pac::Interrupt = pac::Interrupt::ADC1_2;
    #[cfg(feature = "spi-converters")]
    pub const CONTROL_IRQ: pac::Interrupt = pac::Interrupt::TIM2;

    impl Clock for Dwt {
        #[inline(always)]
        fn now(&self) -> u32 {
            DWT::cycle_count()
        }
        #[inline(always)]
        fn elapsed(&self, start: u32, end: u32) -> u32 {
            end.wrapping_sub(start)
        }
        #[inline(always)]
        fn period(&self) -> u32 {
            self.period_cycles
        }
        /// The control interrupt pending again (its flag is cleared by the period's
        /// sample read, so this is the next trigger).
        #[inline(always)]
        fn next_due(&self) -> bool {
            cortex_m::peripheral::NVIC::is_pending(CONTROL_IRQ)
        }
        /// TIM2's count since the trigger, in core cycles (modulo one period: a start a
        /// whole period late reads small, which `periods_between` then shows).
        #[inline(always)]
        fn since_trigger(&self, _now: u32) -> Option<u32> {
            // SAFETY: a read of TIM2_CNT, which no read changes (the control task owns
            // TIM2; reading its counter has no side effect).
            #[allow(unsafe_code)]
            let cnt = unsafe { (*pac::TIM2::ptr()).cnt.read().bits() };
            let ticks = cnt
                .wrapping_add(self.ticks)
                .wrapping_sub(self.trigger_count)
                .checked_rem(self.ticks)?;
            Some(ticks.wrapping_mul(self.cycles_per_tick))
        }
        /// Whole periods between two triggers on the DWT counter (wraps after 10 s).
        #[inline(always)]
        fn periods_between(&self, from: u32, to: u32) -> Option<u32> {
            to.wrapping_sub(from)
                .wrapping_add(self.period_cycles / 2)
                .checked_div(self.period_cycles)
        }
    }

    /// USART3's transmitter as the command port.
    pub struct Usart3 {
        pub tx: serial::Tx<pac::USART3>,
    }

    impl Port for Usart3 {
        /// One reply line, blocking (low priority; 115200 Bd: the holding register always
        /// drains, the control task preempts the wait).
        fn send(&mut self, line: &str) {
            use stm32h7xx_hal::hal::serial::Write;
            for &b in line.as_bytes().iter().chain(b"\r\n") {
                while let Err(stm32h7xx_hal::nb::Error::WouldBlock) = self.tx.write(b) {}
            }
        }
        /// The packets of `rec bin`, blocking as [`Usart3::send`].
        fn send_bytes(&mut self, bytes: &[u8]) {
            use stm32h7xx_hal::hal::serial::Write;
            for &b in bytes {
                while let Err(stm32h7xx_hal::nb::Error::WouldBlock) = self.tx.write(b) {}
            }
        }
        fn selftest(&mut self, r: &mut Reply<REPLY_LEN>) -> Result<(), Error> {
            super::selftest::run::<Conv>(r);
            Ok(())
        }
    }
}

#[cfg(target_os = "none")]
#[rtic::app(device = stm32h7xx_hal::pac, peripherals = true)]
mod app {
    use super::settings::{settings_flash, SettingsBank};
    use super::{safe, Conv, Ctl, Dwt, Hw, Io, Usart3, OVERHEAD_CYCLES, SYSCLK_HZ, WATCHDOG_MS};
    use core::sync::atomic::Ordering::Relaxed;
    use cortex_m::peripheral::DWT;
    use piezo_core::firmware::{
        c, control_period, solve_nmpc, Boot, Budget, CommandLine, SAMPLE_HZ,
    };
    use piezo_core::firmware::{run_flash_job, FlashWork, SettingsFlash, SettingsJob, WithFlash};
    use stm32h7xx_hal::flash::FlashExt;
    use stm32h7xx_hal::{
        delay::Delay, independent_watchdog::IndependentWatchdog, pac, prelude::*, serial,
    };

    #[shared]
    struct Shared {
        ctl: Ctl,
        /// `save`/`load` handed from the command task to idle.
        job: SettingsJob,
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
        port: Usart3,
        cli: CommandLine<Conv>,
        /// Bank 2's settings sectors, idle's alone (`None`: no settings flash).
        settings: Option<SettingsFlash<SettingsBank>>,
        work: FlashWork,
        /// The last boot faulted reading the settings: idle erases them first.
        erase_settings: bool,
        /// The boot's read stopped at an erase its repair needs: idle repairs first.
        repair_settings: bool,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cp = cx.core;
        let dp = cx.device;
        // Before anything that can fail: watchdog (frozen under the debugger), reset cause,
        // amplifier off, on-chip DAC at the safe code (0: SAFE_VOLTS = 0 V at the DAC
        // scale's 0 V code; the pipeline's own value is checked below).
        safe::early(&dp.IWDG, &dp.DBGMCU, &dp.RCC, 0);
        // The caches on (ITCM was loaded at reset, `__pre_init`; DTCM, which holds the
        // stack and the control state, is never cached; no DMA shares memory with the CPU).
        cp.SCB.enable_icache();
        cp.SCB.enable_dcache(&mut cp.CPUID);
        // Bank 2's settings sectors (the SCB goes with them: their cache maintenance).
        let (_, bank2) = dp.FLASH.split();
        let mut settings = settings_flash(bank2, cp.SCB);
        let safe_code = safe::safe_code::<Conv>();
        safe::SAFE_CODE.store(safe_code, Relaxed);
        #[cfg(not(feature = "spi-converters"))]
        {
            safe::dac1::set(0, safe_code as u16);
            safe::dac1::set(1, safe_code as u16);
        }
        let rsr = safe::RESET_FLAGS.load(Relaxed);
        defmt::info!(
            "reset cause: {} (RCC_RSR {=u32:#010x})",
            safe::reset_cause(rsr),
            rsr
        );

        let pwrcfg = dp.PWR.constrain().freeze();
        // The ST-LINK's 8 MHz MCO into PH0 (HSE bypass, Nucleo-144 default solder bridges):
        // a crystal-accurate sample rate instead of HSI's +-1 %. Started here with a bounded
        // wait; without it the PLL runs from HSI and the boot log says so.
        let hse = safe::hse_start(&dp.RCC);
        let rcc = dp.RCC.constrain();
        let rcc = if hse {
            rcc.use_hse(8.MHz()).bypass_hse()
        } else {
            rcc
        };
        // PLL2P: ADC kernel clock; PLL1Q: SPI1 kernel clock (SPI4 runs from PCLK2).
        let mut ccdr = rcc
            .sys_ck(SYSCLK_HZ.Hz())
            .pll1_q_ck(100.MHz())
            .pll2_p_ck(72.MHz())
            .freeze(pwrcfg, &dp.SYSCFG);
        if hse {
            safe::css_on();
            defmt::info!("clock: HSE 8 MHz (bypass), clock security system on");
        } else {
            defmt::warn!("clock: HSE did not start: PLL from HSI 64 MHz, sample rate +-1 %");
        }
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
            // DAC1 channel 1 on PA4 (xy: channel 2 on PA5) runs since `safe::early`.
            // ADC1 (xy: and ADC2), 16 bit, triggered by TIM2 TRGO.
            // ADC2: the y sensor (xy), else `selftest`'s conversion of the DAC pin PA4.
            #[allow(unused_mut)] // only xy configures it through the HAL
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
            #[cfg(not(feature = "xy"))]
            {
                let _dac_pin = gpioa.pa4.into_analog();
                // Enabled and calibrated by the HAL; its registers are `dac_pin`'s now.
                let _ = adc2;
                crate::onchip::dac_pin::setup();
            }
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
            exact_period(timer.inner_mut(), ccdr.clocks.timx_ker_ck().raw());
            timer.inner_mut().cr2.modify(|_, w| w.mms().update());
            Io {
                adc,
                #[cfg(feature = "xy")]
                adc2,
                timer,
            }
        };
        #[cfg(feature = "spi-converters")]
        let io = {
            use crate::spi::{CycleDelay, Gpio, HardwarePin, SpiDev};
            use crate::spi_pair::{Adc, AdcSetup, Dac, DacSetup};
            use piezo_core::firmware::{ADC_CONFIG, DAC_CONFIG};
            use stm32h7xx_hal::gpio::Speed;
            use stm32h7xx_hal::spi;
            let gpiob = dp.GPIOB.split(ccdr.peripheral.GPIOB);
            let gpioe = dp.GPIOE.split(ccdr.peripheral.GPIOE);
            // Every converter line at GPIO speed High (OSPEEDR = 10): the reset speed (Low)
            // is specified for about 12 MHz at 3.3 V and 10 pF (DS12110, I/O AC
            // characteristics), short of the 25 MHz SCK; High covers it with edges of a few
            // ns, Very high would only add ringing on the converters' lines.
            // SYNC and LDAC high (idle) before SPI4 clocks anything.
            let sync = Gpio(gpioe.pe4.into_push_pull_output().speed(Speed::High));
            let ldac = Gpio(gpiob.pb3.into_push_pull_output().speed(Speed::High));
            let dac_bus: spi::Spi<_, _, u8> = dp.SPI4.spi(
                (
                    gpioe.pe2.into_alternate::<5>().speed(Speed::High),
                    gpioe.pe5.into_alternate::<5>().speed(Speed::High),
                    gpioe.pe6.into_alternate::<5>().speed(Speed::High),
                ),
                spi::MODE_1,
                25.MHz(),
                ccdr.peripheral.SPI4,
                &ccdr.clocks,
            );
            let spi4_hz = spi::Spi::<pac::SPI4, spi::Enabled, u8>::kernel_clk_unwrap(&ccdr.clocks);
            // The DAC first: released from its power-on clamp only at the safe code (read
            // back); on failure it stays clamped (0 V) and the board halts in the safe state.
            let mut dac = DacSetup::new(
                SpiDev::new(dac_bus, sync, spi4_hz.raw()),
                ldac,
                CycleDelay,
                DAC_CONFIG,
            )
            .unwrap_or_else(|_| safe::halt());
            if dac.init(safe_code).is_err() {
                defmt::error!("AD5791 did not come up at the safe code: halted, output clamped");
                safe::halt();
            }
            let adc_bus: spi::Spi<_, _, u8> = dp.SPI1.spi(
                (
                    gpioa.pa5.into_alternate::<5>().speed(Speed::High),
                    gpioa.pa6.into_alternate::<5>().speed(Speed::High),
                    gpiob.pb5.into_alternate::<5>().speed(Speed::High),
                ),
                spi::MODE_0,
                25.MHz(),
                ccdr.peripheral.SPI1,
                &ccdr.clocks,
            );
            let spi1_hz = spi::Spi::<pac::SPI1, spi::Enabled, u8>::kernel_clk_unwrap(&ccdr.clocks);
            // CNV (PA0) as a GPIO while configuring: register access needs CNV frames the
            // driver times; then PA0 goes to TIM2 CH1 (AF1) for the loop.
            let cnv = Gpio(gpioa.pa0.into_push_pull_output().speed(Speed::High));
            let mut setup = AdcSetup::new(
                SpiDev::new(adc_bus, HardwarePin, spi1_hz.raw()),
                cnv,
                CycleDelay,
                ADC_CONFIG,
            )
            .unwrap_or_else(|_| safe::halt());
            if setup.init().is_err() {
                defmt::error!("AD4020 did not take its configuration: halted in the safe state");
                safe::halt();
            }
            let (adc_bus, cnv, delay) = setup.release();
            let _cnv = cnv.0.into_alternate::<1>().speed(Speed::High);
            let adc =
                Adc::new(adc_bus, HardwarePin, delay, ADC_CONFIG).unwrap_or_else(|_| safe::halt());
            // TIM2: CH1 in PWM mode 1 is CNV, high for 1/20 of the period from the update
            // event on; its compare interrupt (CNV falls) runs the control task.
            let mut timer = dp
                .TIM2
                .timer(SAMPLE_HZ.Hz(), ccdr.peripheral.TIM2, &ccdr.clocks);
            timer.pause();
            exact_period(timer.inner_mut(), ccdr.clocks.timx_ker_ck().raw());
            let tim = timer.inner_mut();
            let arr = tim.arr.read().arr().bits();
            tim.ccr1().write(|w| w.ccr().bits(arr / 20 + 1));
            tim.ccmr1_output()
                .modify(|_, w| w.oc1m().pwm_mode1().oc1pe().set_bit());
            tim.ccer.modify(|_, w| w.cc1e().set_bit());
            tim.dier.modify(|_, w| w.cc1ie().set_bit());
            // CH2 in PWM mode 2 is LDAC: low from the update event for 1/40 of the period
            // (250 ns at 100 kHz, > the AD5791's 13 ns), high while the control task writes
            // the DAC register; paused at 0 it is low (the safe code, already loaded, stays).
            tim.ccr2().write(|w| w.ccr().bits(arr / 40 + 1));
            tim.ccmr1_output()
                .modify(|_, w| w.oc2m().pwm_mode2().oc2pe().set_bit());
            tim.ccer.modify(|_, w| w.cc2e().set_bit());
            let (dac_bus, ldac, delay) = dac.release();
            let _ldac = ldac.0.into_alternate::<1>().speed(Speed::High);
            let dac =
                Dac::new(dac_bus, HardwarePin, delay, DAC_CONFIG).unwrap_or_else(|_| safe::halt());
            Io {
                adc,
                dac,
                timer,
                held: safe_code,
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

        // The control state, with the stored settings if a valid record is there (read
        // before the first sample, and within the boot watchdog's 100 ms, not the loop's 10).
        let mut ctl = Ctl::with_recorder(
            c(SAMPLE_HZ as f64),
            super::recorder_storage().unwrap_or(&mut []),
        );
        // Modes whose worst step (the M4F's instructions, taken as M7 cycles: one per cycle
        // from ITCM/DTCM, not measured on a board) does not fit the period are refused
        // (err 18).
        let mut cli = CommandLine::for_new(
            c(SAMPLE_HZ as f64),
            Budget::m4f(SYSCLK_HZ / SAMPLE_HZ, OVERHEAD_CYCLES),
        );
        let faulted_before = super::settings::mark_read(true);
        let mut repair_settings = false;
        match settings.as_mut() {
            None => defmt::warn!("settings: no settings flash (bank 2), defaults"),
            // Erased from idle (about 4 s: longer than the boot watchdog; the loop feeds
            // it meanwhile).
            Some(_) if faulted_before => defmt::warn!(
                "settings: the last boot faulted reading them (flash ECC?): defaults; idle erases the sectors"
            ),
            Some(f) => match cli.boot_settings(&mut rtic_core::Exclusive(&mut ctl), f) {
                Boot::Loaded => defmt::info!("settings: stored settings loaded"),
                Boot::Empty => defmt::info!("settings: none stored, defaults"),
                Boot::Refused(e) => defmt::warn!(
                    "settings: stored record refused (err {=u8}), defaults",
                    e.code()
                ),
                // The erase (seconds) runs in idle, where the loop feeds the watchdog.
                Boot::Repair => {
                    repair_settings = true;
                    defmt::warn!("settings: an interrupted save needs a repair: defaults; idle repairs, then `load`")
                }
            },
        }
        super::settings::mark_read(false);

        // Independent watchdog (LSI clock, survives a main-clock failure): only a control
        // period that met its deadline feeds it, so a stalled or overrunning loop resets
        // the MCU, whose DAC then comes up at its safe code.
        let mut watchdog = IndependentWatchdog::new(dp.IWDG);
        watchdog.start(stm32h7xx_hal::time::MilliSeconds::from_ticks(WATCHDOG_MS));

        // The on-chip DAC loads its output on TIM2's trigger from now on.
        #[cfg(not(feature = "spi-converters"))]
        safe::dac1::trigger_from_tim2();
        // No stale flag before the first sample: a conversion or compare event left from the
        // set-up would run the first period on an old sample or at the wrong time.
        let mut io = io;
        clear_control_flags(&mut io);
        let tim = io.timer.inner();
        let ticks = tim.arr.read().arr().bits().wrapping_add(1);
        #[cfg(not(feature = "spi-converters"))]
        let trigger_count = 0;
        #[cfg(feature = "spi-converters")]
        let trigger_count = tim.ccr1().read().ccr().bits();
        let cycles_per_tick = SYSCLK_HZ / ccdr.clocks.timx_ker_ck().raw().max(1);
        // TIM2 last: from here on samples arrive.
        io.timer.resume();
        safe::amp::set(false); // on from the first period without a fault
        let hw = Hw {
            io,
            watchdog,
            clock: Dwt {
                period_cycles: SYSCLK_HZ / SAMPLE_HZ,
                cycles_per_tick,
                ticks,
                trigger_count,
            },
        };

        defmt::info!("firmware up: {} Hz sample rate", SAMPLE_HZ);
        (
            Shared {
                ctl,
                job: SettingsJob::new(),
            },
            Local {
                #[cfg(not(feature = "spi-converters"))]
                hw_adc: hw,
                #[cfg(feature = "spi-converters")]
                hw_spi: hw,
                rx,
                port: Usart3 { tx },
                cli,
                settings,
                work: FlashWork::new(),
                erase_settings: faulted_before,
                repair_settings,
            },
        )
    }

    /// Clears the converters' and TIM2's event flags and the control interrupt's pending
    /// bit (interrupts are still off: RTIC enables them after `init`).
    fn clear_control_flags(io: &mut Io) {
        #[cfg(not(feature = "spi-converters"))]
        {
            // ADC_ISR: write 1 to clear (EOC, EOS, OVR).
            io.adc
                .inner()
                .isr
                .write(|w| w.eoc().set_bit().eos().set_bit().ovr().set_bit());
            #[cfg(feature = "xy")]
            io.adc2
                .inner()
                .isr
                .write(|w| w.eoc().set_bit().eos().set_bit().ovr().set_bit());
        }
        // TIM2_SR: write 0 to clear (update, compare and capture flags).
        // SAFETY: 0 clears every flag; no reserved bit is set.
        #[allow(unsafe_code)]
        io.timer.inner().sr.write(|w| unsafe { w.bits(0) });
        cortex_m::peripheral::NVIC::unpend(super::CONTROL_IRQ);
    }

    /// TIM2's period to exactly 1 / SAMPLE_HZ: the HAL loads ARR with the tick count, but
    /// the period is ARR + 1 ticks (RM0433 "upcounting mode"): 2001 ticks of 200 MHz, 99.95
    /// kHz. Prescaler 1 (the HAL's for these rates).
    fn exact_period(tim: &pac::tim2::RegisterBlock, ker_hz: u32) {
        let ticks = ker_hz / SAMPLE_HZ;
        if ticks * SAMPLE_HZ != ker_hz {
            defmt::warn!(
                "TIM2 kernel clock {=u32} Hz is no multiple of the {=u32} Hz sample rate",
                ker_hz,
                SAMPLE_HZ
            );
        }
        tim.psc.write(|w| w.psc().bits(0));
        tim.arr.write(|w| w.arr().bits(ticks.saturating_sub(1)));
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
        period(cx.local.hw_adc, &mut cx.shared.ctl);
    }

    /// The control period, SPI converters: TIM2 CC1 (CNV fell, the conversion is done).
    #[cfg(feature = "spi-converters")]
    #[task(binds = TIM2, priority = 3, shared = [ctl], local = [hw_spi])]
    fn sample_tim(mut cx: sample_tim::Context) {
        period(cx.local.hw_spi, &mut cx.shared.ctl);
    }

    /// The library's control period; the watchdog is fed only when the deadline held. At
    /// an MPC boundary of a deferred NMPC it pends the solver.
    #[inline(always)]
    fn period(hw: &mut Hw, ctl: &mut impl rtic::Mutex<T = Ctl>) {
        if control_period(&mut hw.io, &hw.clock, ctl) {
            hw.watchdog.feed();
        }
        if ctl.lock(|c| c.nmpc_waiting()) {
            rtic::pend(stm32h7xx_hal::pac::Interrupt::CEC);
        }
    }

    /// NMPC's solve, deferred from the control step (priority 2: under the control task,
    /// over the command line). Bound to HDMI-CEC's interrupt line, which this board never
    /// enables: only the control task pends it.
    #[task(binds = CEC, priority = 2, shared = [ctl])]
    fn solver(mut cx: solver::Context) {
        solve_nmpc(&mut cx.shared.ctl);
    }

    /// Command lines from the serial port (priority 1; the control task preempts it), and
    /// the replies of `save`/`load` when idle has run them (idle pends this task).
    #[task(binds = USART3, priority = 1, shared = [ctl, job], local = [rx, port, cli])]
    fn serial_rx(mut cx: serial_rx::Context) {
        use stm32h7xx_hal::hal::serial::Read;
        let mut port = WithFlash {
            port: cx.local.port,
            job: &mut cx.shared.job,
        };
        cx.local.cli.flash_poll(&mut cx.shared.ctl, &mut port);
        while let Ok(byte) = cx.local.rx.read() {
            cx.local.cli.byte(byte, &mut cx.shared.ctl, &mut port);
        }
    }

    /// `save`/`load` on the settings flash, and timing and overruns over defmt once per
    /// second (DWT cycle counter), from thread mode: the only context besides `init` that
    /// logs or touches the flash.
    #[idle(shared = [ctl, job], local = [settings, work, erase_settings, repair_settings])]
    fn idle(mut cx: idle::Context) -> ! {
        if let (true, Some(f)) = (*cx.local.erase_settings, cx.local.settings.as_mut()) {
            let erased = f.erase_all().is_ok();
            defmt::warn!("settings: sectors erased ({=bool})", erased);
        }
        if let (true, Some(f)) = (*cx.local.repair_settings, cx.local.settings.as_mut()) {
            match f.repair() {
                Ok(stored) => defmt::warn!(
                    "settings: repaired, a record stored: {=bool} (`load` installs it)",
                    stored
                ),
                Err(e) => defmt::warn!("settings: repair failed (err {=u8})", e.code()),
            }
        }
        let mut last = DWT::cycle_count();
        loop {
            if run_flash_job(
                &mut cx.shared.job,
                cx.local.work,
                cx.local.settings.as_mut(),
            ) {
                rtic::pend(pac::Interrupt::USART3);
            }
            if DWT::cycle_count().wrapping_sub(last) < SYSCLK_HZ {
                continue;
            }
            last = last.wrapping_add(SYSCLK_HZ);
            let t = cx.shared.ctl.lock(|c| c.timing);
            defmt::info!(
                "step cycles min {} max {} last {} | isr min {} max {} last {} | start after trigger max {} | samples {} overruns {} lost {}",
                t.step.min, t.step.max, t.step.last, t.isr.min, t.isr.max, t.isr.last,
                t.delay.max, t.isr.count, t.overruns, t.lost
            );
        }
    }
}
