//! Subcommands of the `piezo` binary, one module each.
pub mod demo;
