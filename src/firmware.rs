//! The firmware's board-independent part: what every board runs, built once here and used
//! by the board binaries (`src/bin/h743.rs`, `src/bin/qemu.rs`) and the tests alike.
//!
//! * [`control_period`]: one control period (ADC codes in, pipeline step, DAC codes out,
//!   recorder, timing), over the board's [`Io`] and [`Clock`];
//! * [`CommandLine`]: the serial command line (line buffer, parser, [`Ctl::execute`], the
//!   streamed `rec read`), over the board's [`Port`];
//! * [`Ctl`]: the control state the two share (the [`Loop`] of axes, the recorder, the
//!   timing, the point table) and the command executor;
//! * [`Params`] and the laws and compensators by name ([`law_with`], [`ff_with`]);
//! * [`SettingsFlash`]: the settings record in NOR flash (`save`, `load`, `defaults`),
//!   and [`RamNor`], the strict RAM-backed NOR flash of the QEMU board and the tests;
//! * [`Converters`]: the converter pairs a board can have ([`OnChip`], [`SpiPair`]) and the
//!   sensor and DAC scalings that follow from them.
//!
//! The number type [`R`], the sample rate and the axis count follow the target and the
//! features: `f32` at 100 kHz with an FPU (and on the host), Q16.16 at 16 384 Hz without
//! one; two axes with feature `xy`.

mod budget;
mod console;
mod control_loop;
mod converters;
mod ctl;
mod execute;
mod flash_job;
mod laws;
mod nor;
mod params;
mod period;
pub mod reset;
mod selftest;
mod settings;
mod storage;
mod target;
mod timing;

pub use budget::{
    Budget, SOLVER_LOCK_M4F_BUILD, SOLVE_M4F, SOLVE_M4F_BUILD, SOLVE_M4F_XY, WORST_M4F,
    WORST_M4F_BUILD, WORST_M4F_XY,
};
pub use console::{CommandLine, Port, Replica, WithFlash};
pub use control_loop::Loop;
pub use converters::{
    converter_config, ActuatorDac, Converters, OnChip, PositionAdc, SpiPair, ADC_CONFIG,
    DAC_CONFIG, SPI_CENTER_UM, SPI_SPAN_UM,
};
pub use ctl::{Ctl, PointTable};
pub use execute::{push_real, push_stats, stream_bin, stream_frames, PARAMS, READ_ONLY};
pub use flash_job::{run_flash_job, FlashDone, FlashOp, FlashWork, SettingsJob};
pub use laws::{
    ff_by_name, ff_with, law_by_name, law_with, FFS, LAWS, NMPC_DECIMATION, STAGE_POLE_PER_S,
};
pub use nor::{Blocking, NorError, RamNor};
pub use params::Params;
pub use period::{control_period, solve_nmpc, Clock, Io};
pub use selftest::{dac_scale, push_dac_readback, push_dac_scale, DacScale};
pub use settings::{setting, Access, Setting, SETTINGS};
pub use storage::{decode, encode, stored, Boot, Record, SettingsFlash, MAX_RECORD, VERSION};
pub use target::{
    c, LoopPipeline, RecStorage, AXES, FIXED, R, REC_CH, REC_N, REPLY_LEN, SAFE_VOLTS, SAMPLE_HZ,
};
pub use timing::{CycleStats, NmpcCounts, Timing};

/// Defines a board's `recorder_storage() -> Option<RecStorage>`: `$frames` frames of
/// [`REC_CH`] values in the NOLOAD linker section `$section` (nothing copies or zeroes it
/// at reset), zeroed on the one call that gets it (`None` on a second call). A macro because
/// the section and size are the board's (its linker script) and the static must live in the
/// board's binary.
#[macro_export]
macro_rules! recorder_storage {
    ($section:literal, $frames:expr) => {
        /// The recorder's storage (see [`piezo_core::recorder_storage`]).
        #[allow(unsafe_code)]
        pub fn recorder_storage() -> Option<$crate::firmware::RecStorage> {
            use core::mem::MaybeUninit;
            use core::sync::atomic::{AtomicBool, Ordering};
            use $crate::firmware::{R, REC_CH};
            use $crate::Real;
            #[unsafe(link_section = $section)]
            static mut STORAGE: MaybeUninit<[[R; REC_CH]; $frames]> = MaybeUninit::uninit();
            static TAKEN: AtomicBool = AtomicBool::new(false);
            if TAKEN.swap(true, Ordering::Relaxed) {
                return None;
            }
            // SAFETY: `TAKEN` lets this run once, so the slice is the only reference to
            // `STORAGE` ever made; every frame is written before the slice is formed.
            unsafe {
                let p = core::ptr::addr_of_mut!(STORAGE).cast::<[R; REC_CH]>();
                for i in 0..$frames {
                    p.add(i).write([R::ZERO; REC_CH]);
                }
                Some(core::slice::from_raw_parts_mut(p, $frames))
            }
        }
    };
}

/// Defines the `HardFault` symbol (the vector table's entry) as an assembly entry that sets
/// MSP to the stack's top (`_stack_start`, the vector table's initial SP) before anything
/// touches the stack, then branches to `$halt` (an `extern "C" fn() -> !`: the board's safe
/// state). flip-link puts the stack at the bottom of RAM, so an overflow faults with SP at
/// the RAM's edge: the core still enters HardFault, but a push there faults again at
/// priority -1, a lockup that leaves the DAC where it was until the watchdog resets.
/// Nothing below the stack's top is needed again: `$halt` never returns. Assembly, since a
/// Rust function may push in its prologue. Invoke inside a module that allows
/// `unsafe_code`; `.ci/firmware-safety.py` checks the entry in the H743's ELF and
/// `30-qemu.sh` overflows the QEMU board's stack.
#[macro_export]
macro_rules! hard_fault_entry {
    ($halt:path) => {
        core::arch::global_asm!(
            ".section .HardFault.user, \"ax\"",
            ".global HardFault",
            ".type HardFault, %function",
            ".thumb_func",
            "HardFault:",
            "ldr r0, =_stack_start",
            "msr msp, r0",
            "isb",
            "b {halt}",
            ".ltorg",
            ".size HardFault, . - HardFault",
            halt = sym $halt,
        );
    };
}
