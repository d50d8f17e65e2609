//! Piezo stage controller firmware (RTIC 2).
//!
//! Board-independent code: [`control`]. Each board is one module selected by a cargo
//! feature (exactly one): `board-h743` (default, Nucleo-H743ZI2) or `board-qemu`
//! (QEMU mps2-an386 with a simulated stage, for CI). Feature `xy` builds the two-axis XY
//! scanner (`Pipeline<_, 2>`, raster and Lissajous scans; on-chip converters on the H743).
//!
//! Build and flash: `cargo run --release --target thumbv7em-none-eabihf --bin firmware`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[path = "firmware/control.rs"]
mod control;

#[cfg(all(target_os = "none", feature = "board-h743", feature = "board-qemu"))]
compile_error!("select exactly one board feature: board-h743 or board-qemu");

#[cfg(all(target_os = "none", feature = "board-h743"))]
#[path = "firmware/board_h743.rs"]
mod board_h743;
#[cfg(all(target_os = "none", feature = "board-h743"))]
use {defmt_rtt as _, panic_probe as _};

#[cfg(all(target_os = "none", feature = "board-qemu"))]
#[path = "firmware/board_qemu.rs"]
mod board_qemu;
#[cfg(all(target_os = "none", feature = "board-qemu"))]
use {cortex_m_rt as _, defmt_semihosting as _};

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("firmware: build with --target thumbv7em-none-eabihf");
}
