//! Piezo stage controller firmware (RTIC 2). Build for the target:
//! `cargo build --release --target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("firmware: build with --target thumbv7em-none-eabihf");
}
