//! The host's wire client for the firmware's command protocol ([`piezo_core::command`]:
//! one ASCII line per command, one `ok ...` or `err <code> <message>` reply line; `rec
//! read` and `bench` send data lines before it).
//!
//! * [`link`]: the byte stream, a serial port or TCP (QEMU's UART on a socket);
//! * [`lines`]: command lines built from the core's [`Command`](piezo_core::command::Command)
//!   enum and checked with the firmware's own parser before they are sent, so host and
//!   firmware cannot drift apart;
//! * [`client`]: sync, send, receive and reply classification;
//! * [`replies`]: typed replies (`get`, `stats`, `rec status`, `rec sel`, `rec read` frames);
//! * [`error`]: why a command failed, with the firmware's numbered errors named;
//! * [`bulk`]: the recorder's frames over the framed binary `rec bin` (COBS packets with a
//!   CRC-32 each; damaged ones asked for again).
//!
//! The `piezo serial` subcommands ([`crate::cli::serial`]) and the tests use this module;
//! it knows nothing of the command line.
pub mod bulk;
pub mod client;
pub mod error;
pub mod lines;
pub mod link;
pub mod replies;

pub use client::{Client, Response};
pub use error::SerialError;
pub use link::Link;
