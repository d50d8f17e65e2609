//! Subcommands of the `piezo` binary, one module each.
pub mod demo;
pub mod diagnose;
pub mod diagnose_bench;
pub mod faults;
pub mod fit;
pub mod fit_args;
pub mod fit_ss;
pub mod predict;
pub mod score;
pub mod serial;
pub mod sim;
pub mod ui;
