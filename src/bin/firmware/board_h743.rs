//! Nucleo-H743ZI2 (STM32H743ZI): everything board-specific lives here.
//!
//! * TIM2 overflows at the sample rate; its update event (TRGO) starts an ADC1 conversion in
//!   hardware, so the sampling instant does not jitter with interrupt latency.
//! * The ADC1 end-of-conversion interrupt is the highest-priority task: read the sample, run
//!   the step, write the DAC (PA4, DAC1 channel 1).
//! * USART3 (ST-LINK virtual COM port, PD8/PD9, 115200 Bd) carries the command protocol;
//!   its receive interrupt runs at priority 1. Replies are written without `core::fmt`.
//! * Telemetry (timing, overruns) goes over defmt-RTT once per second from `idle`: defmt
//!   logs from thread mode only (init, then idle), never from an interrupt handler, so its
//!   logger lock is never contended and no handler reaches its reentrancy panic. Timing is
//!   kept by the DWT cycle counter: no monotonic timer, no async task, no dispatcher.
//!
//! Analog input: PA3 (ADC12_INP15, CN9 pin 1 "A0" on the Nucleo-144).

pub use crate::control::SAMPLE_HZ;
/// Core clock (Hz): DWT cycle counts are in these cycles.
pub const SYSCLK_HZ: u32 = 400_000_000;
/// Independent watchdog timeout (ms): 1000 control periods without a healthy one.
pub const WATCHDOG_MS: u32 = 10;

#[rtic::app(device = stm32h7xx_hal::pac, peripherals = true)]
mod app {
    use super::{SAMPLE_HZ, SYSCLK_HZ, WATCHDOG_MS};
    use crate::control::{c, stream_frames, Ctl};
    use cortex_m::peripheral::DWT;
    use piezo_core::command::{self as cmd, Command, LineBuffer, RecCmd};
    use stm32h7xx_hal::{
        adc, delay::Delay, independent_watchdog::IndependentWatchdog, pac, prelude::*,
        rcc::rec::AdcClkSel, serial, timer::Timer, traits::DacOut,
    };

    type DacChannel = stm32h7xx_hal::dac::C1<pac::DAC, stm32h7xx_hal::dac::Enabled>;

    #[shared]
    struct Shared {
        ctl: Ctl,
    }

    #[local]
    struct Local {
        adc: adc::Adc<pac::ADC1, adc::Enabled>,
        dac: DacChannel,
        _timer: Timer<pac::TIM2>,
        rx: serial::Rx<pac::USART3>,
        tx: serial::Tx<pac::USART3>,
        line: LineBuffer,
        period_cycles: u32,
        watchdog: IndependentWatchdog,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cp = cx.core;
        let dp = cx.device;

        let pwrcfg = dp.PWR.constrain().freeze();
        let mut ccdr = dp
            .RCC
            .constrain()
            .sys_ck(SYSCLK_HZ.Hz())
            .pll2_p_ck(72.MHz())
            .freeze(pwrcfg, &dp.SYSCFG);
        ccdr.peripheral.kernel_adc_clk_mux(AdcClkSel::Pll2P);

        cp.DCB.enable_trace();
        DWT::unlock();
        cp.DWT.enable_cycle_counter();

        let mut delay = Delay::new(cp.SYST, ccdr.clocks);
        let gpioa = dp.GPIOA.split(ccdr.peripheral.GPIOA);
        let gpiod = dp.GPIOD.split(ccdr.peripheral.GPIOD);

        // DAC1 channel 1 on PA4.
        let dac = dp
            .DAC
            .dac(gpioa.pa4, ccdr.peripheral.DAC12)
            .calibrate_buffer(&mut delay)
            .enable();

        // ADC1, 16 bit, triggered by TIM2 TRGO.
        let mut adc = adc::Adc::adc1(
            dp.ADC1,
            36.MHz(),
            &mut delay,
            ccdr.peripheral.ADC12,
            &ccdr.clocks,
        )
        .enable();
        adc.set_resolution(adc::Resolution::SixteenBit);
        adc.set_sample_time(adc::AdcSampleTime::T_8);
        configure_adc_trigger(adc.inner_mut());
        let mut ain = gpioa.pa3.into_analog();
        adc.start_conversion(&mut ain);

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
        let mut timer = dp
            .TIM2
            .timer(SAMPLE_HZ.Hz(), ccdr.peripheral.TIM2, &ccdr.clocks);
        timer.inner_mut().cr2.modify(|_, w| w.mms().update());
        timer.resume();

        defmt::info!("firmware up: {} Hz sample rate", SAMPLE_HZ);
        (
            Shared {
                ctl: Ctl::new(c(SAMPLE_HZ as f64)),
            },
            Local {
                adc,
                dac,
                _timer: timer,
                rx,
                tx,
                line: LineBuffer::new(),
                period_cycles: SYSCLK_HZ / SAMPLE_HZ,
                watchdog,
            },
        )
    }

    /// ADC1: external trigger TIM2_TRGO (EXTSEL 11, RM0433 table 205), rising edge, and the
    /// end-of-conversion interrupt.
    fn configure_adc_trigger(adc: &mut pac::ADC1) {
        // SAFETY: EXTSEL is a 5-bit field; 11 selects tim2_trgo.
        #[allow(unsafe_code)]
        adc.cfgr
            .modify(|_, w| unsafe { w.extsel().bits(11) }.exten().rising_edge());
        adc.ier
            .modify(|_, w| w.eocie().set_bit().ovrie().clear_bit());
    }

    /// The control period: sample in, step, DAC out. Highest priority.
    #[task(binds = ADC1_2, priority = 3, shared = [ctl], local = [adc, dac, period_cycles, watchdog])]
    fn sample(mut cx: sample::Context) {
        let t0 = DWT::cycle_count();
        let regs = cx.local.adc.inner();
        // Reading DR clears EOC. OVR means a conversion was overwritten: a missed deadline.
        let overrun = regs.isr.read().ovr().bit_is_set();
        if overrun {
            regs.isr.write(|w| w.ovr().set_bit());
        }
        let code = regs.dr.read().bits();
        let period = *cx.local.period_cycles;
        let dac = cx.local.dac;
        let watchdog = cx.local.watchdog;
        cx.shared.ctl.lock(|ctl| {
            let t1 = DWT::cycle_count();
            let dac_code = ctl.lp.step(code);
            let t2 = DWT::cycle_count();
            dac.set_value(dac_code);
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
            let mut reply = cmd::Reply::<160>::new();
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
