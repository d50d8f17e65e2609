//! Firmware for QEMU `mps2-an386` (Cortex-M4F, thumbv7em-none-eabihf, f32 at 100 kHz) and
//! `mps2-an385` (Cortex-M3, thumbv7m-none-eabi, Q16.16 at 16 384 Hz): the RTIC app boots in
//! CI with a simulated stage. The control period and the command line are the library's
//! ([`piezo_core::firmware`]); this board supplies the hardware side:
//!
//! * SysTick (25 MHz in QEMU's mps2 model) fires at the sample rate and runs the control
//!   period at the highest priority. The stage is [`stage::SimStage`]: the CBW model of the
//!   core plus a first-order lag (and a mechanical resonance after the harness line
//!   `resonance <hz> <zeta>`, none by default; `piezo serial bode`'s test finds it). The
//!   harness line `stage <gain> <hysteresis> <creep>` makes the stage differ from the
//!   firmware's built-in model (`piezo serial identify`'s test): `gain` scales the CBW's `d`
//!   and `alpha` (0.5..2), `hysteresis` the loop width on top (`alpha`, 0.25..3), `creep`
//!   adds creep the firmware's model does not have (0..4; [`stage::CREEP_GAINS`]); it
//!   answers `ok stage <g> <h> <c>`, or `err stage: ...` for a value out of range, which
//!   changes nothing. `stage 1 1 0` is the stage of power-up. It sits behind the firmware's real converter drivers: the
//!   control task runs `Ad4000::start_conversion` + `Ad4000::read` and `Ad5791::set_code`
//!   (the drivers of `piezo_core::drivers`, the ones hal-sim runs) over the no_std mock
//!   chips of [`chips`] (an AD4020 whose CNV edge samples the stage, an AD5791 whose LDAC
//!   edge sets the stage's voltage), with the 20-bit codes of the SPI converter pair. With
//!   feature `xy` there are two identical, independent stages, each behind its own pair of
//!   chips ([`io::SimIo`]).
//! * The CMSDK UART0 (0x4000_4000, QEMU `-serial`) carries the command protocol. As on the
//!   H743 (USART3), its receive interrupt runs the command line at priority 1 under the
//!   control task (priority 3), sharing the control state through the same lock: QEMU
//!   measures what a command costs the control loop. The harness lines `flood start` and
//!   `flood stop` frame a command flood and print `flood: <n> commands, max control delay
//!   <k> instructions, overruns <m>` (the delay from SysTick's reload to the control
//!   interrupt's first instruction of its own).
//! * defmt logs go out over semihosting (decode with `defmt-print -e <elf>`).
//! * Run QEMU with `-icount shift=0,sleep=off`: one instruction per virtual ns, and idle
//!   (`wfi`) jumps to the next interrupt. Without `sleep=off` the virtual clock runs in wall
//!   time while idle sleeps, and a host slower than 100 kHz makes periods overrun.
//! * Before the loop starts, `init` measures the instructions per control step of every
//!   feedback law x feedforward combination ([`bench`]; under `-icount shift=0` one
//!   instruction is one virtual ns, so SysTick ticks over N steps count instructions; a loop of
//!   known length calibrates ticks to instructions). The `bench` command prints that table.
//!   The table counts the pipeline step (ADC code in, DAC code out) without the driver
//!   calls; one extra line counts the driver path per sample (both drivers and the mock
//!   chips).
//! * The host ends the run: the line `exit` (this board's test-harness command, not part of
//!   the protocol) makes the app exit through semihosting with status 0 once at least
//!   [`PERIODS_MIN`] periods have run; a host that kills QEMU ends it too. If no command
//!   arrives within [`PERIODS_MAX`] periods it exits with status 1. Nothing depends on how
//!   long the host is silent: a busy host may pause between `piezo serial` calls for any
//!   time without ending the session.
//!
//! Build: `cargo build --release --target thumbv7em-none-eabihf --bin qemu` (or
//! `--target thumbv7m-none-eabi`); `.ci/test.d/30-qemu.sh` runs it.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod bench;
#[cfg(target_os = "none")]
mod chips;
#[cfg(target_os = "none")]
mod io;
#[cfg(target_os = "none")]
mod stage;
#[cfg(target_os = "none")]
mod uart;

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "qemu: build with --target thumbv7em-none-eabihf (mps2-an386) or thumbv7m-none-eabi (mps2-an385)"
    );
}

#[cfg(target_os = "none")]
use board::*;

#[cfg(target_os = "none")]
mod board {
    use super::{bench, chips, io, stage, uart};
    use core::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, Ordering::Relaxed};
    use cortex_m::peripheral::{SCB, SYST};
    use piezo_core::command::{Error, Reply};
    use piezo_core::firmware::{self, Clock, Converters, Port, SpiPair, REPLY_LEN, SAMPLE_HZ};
    use piezo_core::firmware::{RamNor, SettingsFlash};
    use {cortex_m_rt as _, defmt_semihosting as _};

    /// Recorder frames: 3.5 MiB of the 4 MiB RAM (the rest holds the statics, about 30 KiB,
    /// and the stack, whose bound is about 32 KiB): 229 376 frames, 2.3 s at 100 kHz.
    pub const REC_FRAMES: usize = 7 * 32 * 1024;

    // The recorder's storage in RAM: [`REC_FRAMES`] frames of [`REC_CH`] values (3.5 MiB), in the
    // NOLOAD section `.uninit.recorder` (nothing copies or zeroes it at reset); zeroed here once.
    // `None` on a second call.
    piezo_core::recorder_storage!(".uninit.recorder", REC_FRAMES);

    /// The control state over this board's converters (the SPI pair, on mock chips).
    pub type Ctl = firmware::Ctl<SpiPair>;

    /// The settings flash: 4 sectors of 2 KiB, programmed and read in 32-byte words like the
    /// H743's flash (the sector is smaller: QEMU's RAM is the flash).
    pub type SettingsNor = RamNor<8192, 2048, 32>;

    /// The settings flash over all of [`SettingsNor`].
    pub fn settings_flash() -> SettingsFlash<SettingsNor> {
        match SettingsFlash::new(SettingsNor::new(), 0..8192) {
            Ok(f) => f,
            // A compile-time geometry: unreachable, but no panic path for it.
            Err(_) => semihosting::process::exit(1),
        }
    }

    /// SysTick clock of QEMU's mps2 machines (Hz).
    pub const SYSTICK_HZ: u32 = 25_000_000;
    /// Control periods to run before exiting.
    pub const PERIODS_MIN: u32 = 10_000;
    /// Give up (exit 1) when no command was answered after this many periods.
    pub const PERIODS_MAX: u32 = 300_000;
    /// The harness line that ends the run (after [`PERIODS_MIN`] periods).
    const EXIT_LINE: &[u8] = b"exit";
    /// The harness line that forces a panic (after [`PERIODS_MIN`] periods, so the DAC has
    /// left its safe code): the panic handler must put the safe code back (CI checks it).
    const PANIC_LINE: &[u8] = b"panic";
    /// The harness line that overflows the stack (after [`PERIODS_MIN`] periods): the
    /// HardFault entry must reach the safe state on a fresh stack (CI checks it).
    const OVERFLOW_LINE: &[u8] = b"overflow";
    /// The DAC's safe code (the pipeline's safe voltage at the DAC's own scale), set in
    /// `init` before anything else, read by the panic handler.
    pub static SAFE_CODE: AtomicI32 = AtomicI32::new(0);
    /// SysTick ticks per control period.
    const PERIOD: u32 = SYSTICK_HZ / SAMPLE_HZ;
    /// Instructions per SysTick tick under `-icount shift=0` (1 instruction per ns).
    pub const INSTR_PER_TICK: u32 = 1_000_000_000 / SYSTICK_HZ;
    /// The harness asked (serial task) to end the run or to panic (idle acts on it).
    pub static EXIT: AtomicBool = AtomicBool::new(false);
    pub static PANIC: AtomicBool = AtomicBool::new(false);
    pub static OVERFLOW: AtomicBool = AtomicBool::new(false);
    /// Replies sent (serial task), read by idle.
    pub static ANSWERED: AtomicU32 = AtomicU32::new(0);
    /// The harness line that starts a command flood (resets the timing) and the one that
    /// ends it (prints the flood line).
    const FLOOD_START: &[u8] = b"flood start";
    const FLOOD_STOP: &[u8] = b"flood stop";
    /// The harness line `wait <n>`: the serial task reads no further byte until `n` more
    /// control periods have run (the host blocks on the UART meanwhile). A script that needs
    /// the recorder full waits in virtual time, whatever the host's speed.
    const WAIT_PREFIX: &[u8] = b"wait ";
    /// The period at which a `wait` ends (0: none); idle pends the serial task then.
    pub static WAIT_UNTIL: AtomicU32 = AtomicU32::new(0);

    /// The "device" RTIC needs: SysTick and the UART0 receive interrupt.
    pub mod pac {
        /// QEMU's NVIC implements 8 bits; RTIC only needs 3 levels here.
        pub const NVIC_PRIO_BITS: u8 = 3;

        /// The mps2-an385/an386 external interrupts this board uses (QEMU hw/arm/mps2.c).
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[allow(non_camel_case_types, clippy::upper_case_acronyms)]
        pub enum Interrupt {
            /// CMSDK UART0 receive.
            UARTRX0 = 0,
            /// CMSDK UART0 transmit: its interrupt is never enabled, so the line only runs
            /// when software pends it (the NMPC solver task).
            UARTTX0 = 1,
        }

        /// RTIC checks the bound interrupt's name here (a PAC's `rt` re-export).
        pub use self::Interrupt as interrupt;

        // SAFETY: the number is the interrupt's position in the vector table below.
        #[allow(unsafe_code)]
        unsafe impl cortex_m::interrupt::InterruptNumber for Interrupt {
            fn number(self) -> u16 {
                self as u16
            }
        }
    }

    /// The mps2's 32 external interrupts: UART0 receive (0) to its RTIC task, the rest to
    /// the default handler. cortex-m-rt leaves this table to the application with its
    /// `device` feature, which the H743's PAC turns on for eabihf and Cargo.toml for
    /// thumbv7m.
    #[allow(unsafe_code)]
    #[unsafe(link_section = ".vector_table.interrupts")]
    #[unsafe(no_mangle)]
    static __INTERRUPTS: [unsafe extern "C" fn(); 32] = {
        unsafe extern "C" {
            fn DefaultHandler();
            fn UARTRX0();
            fn UARTTX0();
        }
        let mut v: [unsafe extern "C" fn(); 32] = [DefaultHandler; 32];
        v[0] = UARTRX0;
        v[1] = UARTTX0;
        v
    };

    /// SysTick as the cycle counter: it counts down from the period's reload value, so
    /// ticks stand in for cycles (x40 = instructions with `-icount shift=0`).
    pub struct SysTickClock;

    impl Clock for SysTickClock {
        #[inline(always)]
        fn now(&self) -> u32 {
            SYST::get_current()
        }
        /// A reload in between is undone.
        #[inline(always)]
        fn elapsed(&self, start: u32, end: u32) -> u32 {
            let d = start.wrapping_sub(end);
            if d > PERIOD {
                d.wrapping_add(PERIOD)
            } else {
                d
            }
        }
        #[inline(always)]
        fn period(&self) -> u32 {
            PERIOD
        }
        #[inline(always)]
        fn next_due(&self) -> bool {
            SCB::is_pendst_pending()
        }
        /// SysTick counts down to 0 (the trigger, which reads 0 for one tick) and reloads
        /// `PERIOD - 1`: `now` ticks are left of the period.
        #[inline(always)]
        fn since_trigger(&self, now: u32) -> Option<u32> {
            Some(PERIOD.wrapping_sub(now) % PERIOD)
        }
    }

    /// UART0 as the command port, plus this board's `bench` table, `selftest` and the
    /// harness' `exit` and `panic`.
    pub struct Uart {
        pub table: bench::Table,
        /// A harness line asked to start (true) or stop (false) a flood.
        pub flood: Option<bool>,
        /// A harness line asked to wait this many control periods.
        pub wait: Option<u32>,
    }

    /// The harness line `resonance <hz> <zeta>`: the simulated stages get a mechanical
    /// resonance (`resonance 0 0`: none again; see [`stage::RESONANCE_HZ`]). True when the
    /// line is one (out-of-range values leave no resonance).
    fn set_resonance(line: &[u8]) -> bool {
        let Some(rest) = line.strip_prefix(b"resonance ") else {
            return false;
        };
        let Ok(rest) = core::str::from_utf8(rest) else {
            return false;
        };
        let mut words = rest.split(' ');
        let (Some(hz), Some(zeta), None) = (words.next(), words.next(), words.next()) else {
            return false;
        };
        let (Ok(hz), Ok(zeta)) = (
            piezo_core::command::parse_f32(hz),
            piezo_core::command::parse_f32(zeta),
        ) else {
            return false;
        };
        stage::RESONANCE_HZ.store(hz.to_bits(), Relaxed);
        stage::RESONANCE_ZETA.store(zeta.to_bits(), Relaxed);
        stage::RESONANCE_GEN.fetch_add(1, Relaxed);
        true
    }

    /// The harness line `stage <gain> <hysteresis> <creep>`: the simulated stages differ from
    /// the firmware's built-in model (see [`stage::STAGE_GAIN`]; `stage 1 1 0` is the stage of
    /// power-up). Unlike the other harness lines it answers, since a value out of
    /// [`stage::STAGE_RANGES`] must not pass silently: `ok stage <gain> <hysteresis> <creep>`,
    /// or `err stage: gain 0.5..2, hysteresis 0.25..3, creep 0..4` and nothing changes. True
    /// when the line is one.
    fn set_stage(line: &[u8]) -> bool {
        let Some(rest) = line.strip_prefix(b"stage ") else {
            return false;
        };
        let mut v = [f32::NAN; 3];
        let mut words = core::str::from_utf8(rest).unwrap_or("").split(' ');
        for x in v.iter_mut() {
            *x = words
                .next()
                .and_then(|w| piezo_core::command::parse_f32(w).ok())
                .unwrap_or(f32::NAN);
        }
        let checked = match words.next() {
            None => stage::checked_stage(v[0], v[1], v[2]),
            Some(_) => None,
        };
        let Some(scales) = checked else {
            uart::line("err stage: gain 0.5..2, hysteresis 0.25..3, creep 0..4");
            return true;
        };
        for (a, x) in [
            &stage::STAGE_GAIN,
            &stage::STAGE_HYSTERESIS,
            &stage::STAGE_CREEP,
        ]
        .iter()
        .zip(scales)
        {
            a.store(x.to_bits(), Relaxed);
        }
        stage::STAGE_GEN.fetch_add(1, Relaxed);
        let mut r = Reply::<REPLY_LEN>::new();
        r.push_str("ok stage");
        for x in scales {
            // Within 0..4: three decimals say it exactly enough.
            r.push_str(" ");
            r.push_fixed(libm::roundf(x * 1000.0) as u32, 3);
        }
        uart::line(r.as_str());
        true
    }

    /// The harness line `sensor <fault>`: injects `stuck-low`, `stuck-high`, `floating` or
    /// `disconnected` into axis 0's ADC (`none`: healthy again) and answers `ok sensor
    /// <fault>`; `sensor report` answers `sensor: safe after <n> samples` (from the first
    /// faulty conversion to the period that turned the amplifier off, inclusive) or
    /// `sensor: not safe`. True when the line is one.
    fn sensor_line(line: &[u8]) -> bool {
        use io::inject;
        let Some(rest) = line.strip_prefix(b"sensor ") else {
            return false;
        };
        let fault = match rest {
            b"report" => {
                let n = inject::SAFE_AFTER.load(Relaxed);
                let mut r = Reply::<REPLY_LEN>::new();
                if n == u32::MAX {
                    r.push_str("sensor: not safe");
                } else {
                    r.push_str("sensor: safe after ");
                    r.push_u32(n);
                    r.push_str(" samples");
                }
                uart::line(r.as_str());
                return true;
            }
            b"none" => chips::FAULT_NONE,
            b"stuck-low" => chips::FAULT_STUCK_LOW,
            b"stuck-high" => chips::FAULT_STUCK_HIGH,
            b"floating" => chips::FAULT_FLOATING,
            b"disconnected" => chips::FAULT_DISCONNECTED,
            _ => {
                uart::line(
                    "err sensor: none, stuck-low, stuck-high, floating, disconnected, report",
                );
                return true;
            }
        };
        inject::ACTIVE.store(false, Relaxed);
        inject::SAMPLES.store(0, Relaxed);
        inject::SAFE_AFTER.store(u32::MAX, Relaxed);
        chips::set_fault(0, fault);
        inject::ACTIVE.store(fault != chips::FAULT_NONE, Relaxed);
        let mut r = Reply::<REPLY_LEN>::new();
        r.push_str("ok sensor ");
        r.push_str(core::str::from_utf8(rest).unwrap_or("?"));
        uart::line(r.as_str());
        true
    }

    /// The periods of a `wait <n>` line (decimal, 1 ..= [`PERIODS_MAX`]).
    fn wait_periods(line: &[u8]) -> Option<u32> {
        let digits = line.strip_prefix(WAIT_PREFIX)?;
        if digits.is_empty() || digits.len() > 6 {
            return None;
        }
        let mut n = 0u32;
        for &d in digits {
            n = n * 10 + u32::from(d.checked_sub(b'0').filter(|d| *d <= 9)?);
        }
        (1..=PERIODS_MAX).contains(&n).then_some(n)
    }

    impl Port for Uart {
        fn send(&mut self, line: &str) {
            uart::line(line);
        }
        fn send_bytes(&mut self, bytes: &[u8]) {
            uart::write_bytes(bytes);
        }
        fn bench(&mut self) -> Result<usize, Error> {
            bench::print(&self.table, false);
            Ok(bench::ROWS)
        }
        fn harness(&mut self, line: &[u8]) -> bool {
            match line {
                EXIT_LINE => EXIT.store(true, Relaxed),
                PANIC_LINE => PANIC.store(true, Relaxed),
                OVERFLOW_LINE => OVERFLOW.store(true, Relaxed),
                FLOOD_START => self.flood = Some(true),
                FLOOD_STOP => self.flood = Some(false),
                _ => match wait_periods(line) {
                    Some(n) => self.wait = Some(n),
                    None => return set_resonance(line) || set_stage(line) || sensor_line(line),
                },
            }
            true
        }
        /// The next control period reads axis 0's DAC register back after its write (at
        /// the read-back SCLK); plus the last ADC code against the sensor window, the
        /// amplifier enable line and the mock chips' rule violations. The wait for the
        /// period is bounded (idle runs below it, so it comes within one period).
        fn selftest(&mut self, r: &mut Reply<REPLY_LEN>) -> Result<(), Error> {
            use io::selftest::{DONE, IDLE, READ, REQUESTED, STATE, WROTE};
            use piezo_core::firmware::push_dac_readback;
            STATE.store(REQUESTED, Relaxed);
            let mut done = false;
            for _ in 0..10 * SYSTICK_HZ / SAMPLE_HZ * 40 {
                if STATE.load(Relaxed) == DONE {
                    done = true;
                    break;
                }
            }
            STATE.store(IDLE, Relaxed);
            r.push_str(" reset n/a dac ");
            push_dac_readback(r, done.then(|| (READ.load(Relaxed), WROTE.load(Relaxed))));
            let adc = io::selftest::ADC.load(Relaxed);
            let s = <SpiPair as Converters>::sensor(0.0);
            let seen = adc >> <SpiPair as Converters>::ADC_SHIFT;
            r.push_str(" adc ");
            r.push_i32(adc);
            r.push_str(if (s.code_min..=s.code_max).contains(&seen) {
                " in"
            } else {
                " out"
            });
            r.push_str(" amp ");
            r.push_str(if chips::AMP_ON.load(Relaxed) {
                "on"
            } else {
                "off"
            });
            let (n, first) = chips::violations();
            r.push_str(" chips ");
            r.push_u32(n);
            r.push_str(" ");
            r.push_str(first);
            Ok(())
        }
    }

    /// A panic: interrupts off (the control period stops), amplifier off, the safe code
    /// written to every axis' DAC through the same driver (a new instance on the same mock
    /// chip), then the DAC model's output before and after is printed from the mock itself
    /// (CI checks it is the safe code) and the run ends with status 101.
    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        safe_state("panic");
        defmt::error!("panic: {}", defmt::Display2Format(info));
        uart::line("panic");
        semihosting::process::exit(101)
    }

    // A HardFault (the harness' stack overflow among them): the safe state from a fresh
    // stack, reported as the panic is, then status 102.
    #[allow(unsafe_code)]
    mod hard_fault {
        piezo_core::hard_fault_entry!(super::hard_fault);
    }

    extern "C" fn hard_fault() -> ! {
        safe_state("hardfault");
        uart::line("hardfault");
        semihosting::process::exit(102)
    }

    /// The harness' stack overflow: a recursion that keeps a frame of 256 bytes live per
    /// level until the stack runs out of RAM (flip-link: into unmapped memory, a bus fault).
    #[inline(never)]
    #[allow(unconditional_recursion)]
    pub fn overflow_stack(depth: u32) -> u32 {
        let mut frame = [depth as u8; 256];
        let frame = core::hint::black_box(&mut frame);
        u32::from(frame[0]).wrapping_add(overflow_stack(depth.wrapping_add(1)))
    }

    /// Interrupts off, amplifier off, the safe code into every axis' DAC through the driver;
    /// prints `<tag>: dac <axis> out <before> -> <after> safe <code> amp off`.
    fn safe_state(tag: &str) {
        cortex_m::interrupt::disable();
        chips::AMP_ON.store(false, Relaxed);
        let safe = SAFE_CODE.load(Relaxed);
        let before = [chips::dac_out(0), chips::dac_out(1)];
        safe_dac::<0>(safe);
        #[cfg(feature = "xy")]
        safe_dac::<1>(safe);
        for (axis, before) in before.iter().enumerate().take(firmware::AXES) {
            let mut r = Reply::<120>::new();
            r.push_str(tag);
            r.push_str(": dac ");
            r.push_usize(axis);
            r.push_str(" out ");
            r.push_i32(*before);
            r.push_str(" -> ");
            r.push_i32(chips::dac_out(axis));
            r.push_str(" safe ");
            r.push_i32(safe);
            r.push_str(" amp ");
            r.push_str(if chips::AMP_ON.load(Relaxed) {
                "on"
            } else {
                "off"
            });
            uart::line(r.as_str());
        }
    }

    /// Axis `A`'s DAC to `code` through the firmware's driver.
    fn safe_dac<const A: usize>(code: i32) {
        if let Ok(mut dac) = chips::Dac::<A>::new(
            chips::DacSpi,
            chips::Ldac,
            chips::TimerDelay,
            firmware::DAC_CONFIG,
        ) {
            dac.set_code(code).ok();
        }
    }
}

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::pac, peripherals = false)]
mod app {
    use super::io::SimIo;
    use super::{
        bench, chips, recorder_storage, settings_flash, uart, Ctl, SettingsNor, SysTickClock, Uart,
        ANSWERED, EXIT, INSTR_PER_TICK, OVERFLOW, PANIC, PERIODS_MAX, PERIODS_MIN, SAFE_CODE,
        SYSTICK_HZ, WAIT_UNTIL,
    };
    use core::sync::atomic::Ordering::Relaxed;
    use cortex_m::peripheral::syst::SystClkSource;
    use piezo_core::command::Reply;
    use piezo_core::firmware::{c, control_period, solve_nmpc, Boot, CommandLine, AXES, SAMPLE_HZ};
    use piezo_core::firmware::{run_flash_job, FlashWork, SettingsFlash, SettingsJob, WithFlash};
    use piezo_core::firmware::{Converters, SpiPair, Timing};
    use piezo_core::pipeline::Wave;

    #[shared]
    struct Shared {
        ctl: Ctl,
        /// `save`/`load` handed from the command task to idle.
        job: SettingsJob,
    }

    #[local]
    struct Local {
        io: SimIo,
        cli: CommandLine<SpiPair>,
        /// Replies sent when the flood started.
        flood_from: u32,
        port: Uart,
        /// The settings flash (RAM-backed: QEMU keeps nothing across runs), idle's alone.
        settings: SettingsFlash<SettingsNor>,
        work: FlashWork,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut syst = cx.core.SYST;
        // First: the chips' time base, then the DAC at the safe code (the pipeline's safe
        // voltage at the DAC's scale) before anything that can fail; the amplifier stays
        // off until the loop runs without a fault.
        chips::clock::start();
        let ctl = Ctl::with_recorder(c(SAMPLE_HZ as f64), recorder_storage().unwrap_or(&mut []));
        let safe = ctl.lp.p.codes()[0] << <SpiPair as Converters>::DAC_SHIFT;
        SAFE_CODE.store(safe, Relaxed);
        uart::init();
        let io = match SimIo::new(safe) {
            Ok(io) => io,
            Err(rule) => {
                uart::line("error: converters did not come up:");
                uart::line(rule);
                semihosting::process::exit(1)
            }
        };
        defmt::info!("qemu board: bench");
        let table = bench::run(&mut syst);
        bench::print(&table, true);
        #[cfg(target_abi = "eabihf")]
        bench::math(&mut syst, table.instr_per_tick_x1000);
        if option_env!("PIEZO_BENCH_ONLY").is_some() {
            semihosting::process::exit(0);
        }

        let mut ctl = ctl;
        for axis in 0..AXES {
            ctl.lp.p.set_wave(axis, Wave::Hold { y_um: c(10.0) }).ok();
        }
        let mut cli = CommandLine::new(&ctl.lp);
        // Modes whose measured worst step does not fit the period are refused (err 18).
        cli.set_budget(bench::budget(&table));
        // The stored settings, if any (QEMU's flash is RAM: none at power-up).
        let mut settings = settings_flash();
        match cli.boot_settings(&mut rtic_core::Exclusive(&mut ctl), &mut settings) {
            Boot::Loaded => defmt::info!("settings: stored settings loaded"),
            Boot::Empty => defmt::info!("settings: none stored, defaults"),
            Boot::Refused(e) => {
                defmt::warn!(
                    "settings: stored record refused (err {=u8}), defaults",
                    e.code()
                );
                uart::line("warn settings: stored record refused, defaults in use");
            }
            // QEMU's RAM flash starts empty: no save was ever interrupted. Repaired at once
            // here (no watchdog), not from idle as on the H743.
            Boot::Repair => {
                let stored = settings.repair();
                defmt::warn!("settings: repaired ({=bool}), defaults", stored.is_ok());
                uart::line("warn settings: the flash was repaired, defaults in use; `load` installs the stored record");
            }
        }
        // The period's clock starts last: started before the work above, the first period's
        // trigger passed during it and `stats` showed a start 6.6 us after the trigger.
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(SYSTICK_HZ / SAMPLE_HZ - 1);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        defmt::info!("qemu board: control loop at {=u32} Hz", SAMPLE_HZ);
        uart::line("ready");
        (
            Shared {
                ctl,
                job: SettingsJob::new(),
            },
            Local {
                io,
                cli,
                port: Uart {
                    table,
                    flood: None,
                    wait: None,
                },
                flood_from: 0,
                settings,
                work: FlashWork::new(),
            },
        )
    }

    /// The control period: the stage moves under the voltage of the DAC's output, the ADC
    /// driver samples and reads it, the DAC driver writes and loads the new code (every
    /// axis).
    /// Priority 3, as the H743's control task.
    #[task(binds = SysTick, priority = 3, shared = [ctl], local = [io])]
    fn sample(mut cx: sample::Context) {
        control_period(cx.local.io, &SysTickClock, &mut cx.shared.ctl);
        if cx.shared.ctl.lock(|c| c.nmpc_waiting()) {
            rtic::pend(crate::board::pac::Interrupt::UARTTX0);
        }
    }

    /// NMPC's solve, deferred from the control step (priority 2: under the control task,
    /// over the command line; pended by the control task at every MPC boundary).
    #[task(binds = UARTTX0, priority = 2, shared = [ctl])]
    fn solver(mut cx: solver::Context) {
        solve_nmpc(&mut cx.shared.ctl);
    }

    /// Command lines from UART0 (priority 1, under the control task; the H743's USART3
    /// task).
    #[task(binds = UARTRX0, priority = 1, shared = [ctl, job], local = [cli, port, flood_from])]
    fn serial_rx(mut cx: serial_rx::Context) {
        uart::clear_rx_interrupt();
        // A `save`/`load` idle finished (idle pended this task): its reply first.
        let mut port = WithFlash {
            port: &mut *cx.local.port,
            job: &mut cx.shared.job,
        };
        if cx.local.cli.flash_poll(&mut cx.shared.ctl, &mut port) {
            ANSWERED.fetch_add(1, Relaxed);
        }
        if WAIT_UNTIL.load(Relaxed) != 0 {
            // A `wait` runs: the byte stays in the UART (idle pends this task at the end).
            return;
        }
        while let Some(byte) = uart::try_read() {
            let mut port = WithFlash {
                port: &mut *cx.local.port,
                job: &mut cx.shared.job,
            };
            if cx.local.cli.byte(byte, &mut cx.shared.ctl, &mut port) {
                ANSWERED.fetch_add(1, Relaxed);
            }
            match cx.local.port.flood.take() {
                Some(true) => {
                    cx.shared.ctl.lock(|c| c.timing = Timing::new());
                    *cx.local.flood_from = ANSWERED.load(Relaxed);
                }
                Some(false) => {
                    let t = cx.shared.ctl.lock(|c| c.timing);
                    let mut r = Reply::<160>::new();
                    r.push_str("flood: ");
                    r.push_u32(ANSWERED.load(Relaxed).wrapping_sub(*cx.local.flood_from));
                    r.push_str(" commands, max control delay ");
                    r.push_u32(t.delay.max.saturating_mul(INSTR_PER_TICK));
                    r.push_str(" instructions, overruns ");
                    r.push_u32(t.overruns);
                    r.push_str(", max control interrupt ");
                    r.push_u32(t.isr.max.saturating_mul(INSTR_PER_TICK));
                    r.push_str(" instructions, periods ");
                    r.push_u32(t.isr.count);
                    uart::line(r.as_str());
                }
                None => {}
            }
            if let Some(n) = cx.local.port.wait.take() {
                let now = cx.shared.ctl.lock(|c| c.periods);
                // Leave the rest in the UART: idle pends this task again when the periods
                // have run (0 is "no wait", so the end is at least 1).
                WAIT_UNTIL.store(now.saturating_add(n).max(1), Relaxed);
                return;
            }
        }
    }

    /// The harness' requests, `save`/`load` on the settings flash, and the timing over defmt
    /// every [`LOG_PERIODS`] control periods (thread mode only, as on the H743; CI decodes
    /// and checks the lines).
    #[idle(shared = [ctl, job], local = [settings, work])]
    fn idle(mut cx: idle::Context) -> ! {
        // Twenty lines per second of virtual time, where the H743 logs one: a CI run lasts
        // about 0.1 s.
        const LOG_PERIODS: u32 = SAMPLE_HZ / 20;
        let mut window = 0u32;
        loop {
            let periods = cx.shared.ctl.lock(|c| c.periods);
            if periods / LOG_PERIODS != window {
                window = periods / LOG_PERIODS;
                let t = cx.shared.ctl.lock(|c| c.timing);
                defmt::info!(
                    "step cycles min {} max {} last {} | isr min {} max {} last {} | samples {} overruns {}",
                    t.step.min, t.step.max, t.step.last, t.isr.min, t.isr.max, t.isr.last,
                    t.isr.count, t.overruns
                );
            }
            if run_flash_job(&mut cx.shared.job, cx.local.work, Some(cx.local.settings)) {
                rtic::pend(crate::board::pac::Interrupt::UARTRX0);
            }
            let until = WAIT_UNTIL.load(Relaxed);
            if until != 0 && periods >= until {
                WAIT_UNTIL.store(0, Relaxed);
                rtic::pend(crate::board::pac::Interrupt::UARTRX0);
            }
            let answered = ANSWERED.load(Relaxed);
            if PANIC.load(Relaxed) && periods >= PERIODS_MIN {
                panic!("forced by the harness");
            }
            if OVERFLOW.load(Relaxed) && periods >= PERIODS_MIN {
                super::overflow_stack(0);
            }
            if EXIT.load(Relaxed) && periods >= PERIODS_MIN {
                finish(&mut cx.shared.ctl, periods, answered, 0);
            }
            if periods >= PERIODS_MAX && answered == 0 {
                uart::line("error: no command received");
                finish(&mut cx.shared.ctl, periods, answered, 1);
            }
            // Sleep to the next interrupt (the next period at the latest): with QEMU's
            // `-icount sleep=off` the virtual clock jumps there, where a spinning idle made the
            // emulator execute every idle nanosecond (6 000 periods per wall second against
            // 9 300; without sleep=off, idle time passes in wall time and periods overrun).
            cortex_m::asm::wfi();
        }
    }

    fn finish(ctl: &mut impl rtic::Mutex<T = Ctl>, periods: u32, answered: u32, code: i32) -> ! {
        let t = ctl.lock(|c| c.timing);
        let mut r = Reply::<160>::new();
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
        let (n, first) = chips::violations();
        r.clear();
        r.push_str("chips: ");
        r.push_u32(n);
        r.push_str(" data-sheet rule violations, first: ");
        r.push_str(first);
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
