//! What follows from the target and the features: the number type, the sample rate, the
//! axes, and the sizes of the recorder and of a reply.

use crate::Real;

/// The number type of the control path: `f32` with an FPU (thumbv7em-none-eabihf), the
/// Q16.16 fixed point of [`crate::fixed`] without one (thumbv7m-none-eabi, Cortex-M3).
/// (A host build, the tests, takes the f32 variant.)
#[cfg(any(target_abi = "eabihf", not(target_os = "none")))]
pub type R = f32;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub type R = crate::fixed::Q16;

/// The number type is Q16.16 (no FPU): it holds values below 32768, so codes keep 15 bits.
pub const FIXED: bool = cfg!(not(any(target_abi = "eabihf", not(target_os = "none"))));

/// Axes the firmware drives: 2 with feature `xy` (an XY scanner: raster and Lissajous
/// scans), else 1.
pub const AXES: usize = if cfg!(feature = "xy") { 2 } else { 1 };

/// The boards solve NMPC in a task below the control task ([`crate::feedback::Nmpc::set_deferred`]:
/// the control step only applies the plan); the host's in-process firmware solves it in the
/// step, as `piezo sim` does.
pub const NMPC_DEFERRED: bool = cfg!(target_os = "none");

/// The pipeline of the control task: [`crate::pipeline::FirmwarePipeline`] (the type
/// hal-sim runs), [`crate::pipeline::FirmwarePipeline2`] with feature `xy`, with an FPU;
/// their Q16.16 twins without one.
#[cfg(all(
    any(target_abi = "eabihf", not(target_os = "none")),
    not(feature = "xy")
))]
pub type LoopPipeline = crate::pipeline::FirmwarePipeline;
#[cfg(all(any(target_abi = "eabihf", not(target_os = "none")), feature = "xy"))]
pub type LoopPipeline = crate::pipeline::FirmwarePipeline2;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub type LoopPipeline = crate::pipeline::Pipeline<R, AXES>;

/// A constant of the control path (folded at compile time).
#[inline(always)]
pub fn c(x: f64) -> R {
    R::from_f64(x)
}

/// Recorder channels; frames per capture by default (`rec len`: up to the board's storage:
/// the H743's AXI SRAM, most of the QEMU board's RAM; [`Ctl::new`](super::Ctl::new) on the
/// host: 4 x this default).
pub const REC_CH: usize = 4;
pub const REC_N: usize = 1024;
/// The recorder's storage: frames of [`REC_CH`] values a board places in its RAM.
#[cfg(target_os = "none")]
pub type RecStorage = &'static mut [[R; REC_CH]];
/// The recorder's storage on the host: owned, freed with the controller (tests and fuzz
/// targets make many).
#[cfg(not(target_os = "none"))]
pub type RecStorage = std::boxed::Box<[[R; REC_CH]]>;
#[cfg(not(target_os = "none"))]
extern crate std;

/// Sample rate of the control loop (Hz). Q16.16 holds values below 32768 only, so the
/// fixed-point build runs at 16 384 Hz (sample period exactly 4 units of 2^-16 s).
#[cfg(any(target_abi = "eabihf", not(target_os = "none")))]
pub const SAMPLE_HZ: u32 = 100_000;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub const SAMPLE_HZ: u32 = 16_384;

/// Safe state of every axis (V): where the output goes at start-up and on a fault.
pub const SAFE_VOLTS: f64 = 0.0;

/// Capacity of a command's reply line (`help` lists every parameter: 260 bytes with the notch).
pub const REPLY_LEN: usize = 320;
