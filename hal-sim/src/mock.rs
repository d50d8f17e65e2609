//! Mock converters implementing embedded-hal 1.0, as strict as their data sheets: an
//! AD4000-family position ADC ([`MockAdc`], AD4020 by default) and an AD5791 DAC
//! ([`MockDac`]) with their register maps, code formats and frame layout, quantisation,
//! offset and gain error, noise and conversion latency, and the interface rules a real part
//! needs (CNV frames and the SDI level for the ADC's register access and reads, `t_CONV`,
//! SCLK limits, the LDAC pulse, the DAC's power-on clamp and code). A broken rule fails
//! loudly: the transaction or pin edge returns an error and the chip records the
//! [`Violation`] (count and first one), so a driver or board sequence the real part would
//! not accept fails a test here.
//!
//! Each chip is one shared state (`Rc<RefCell<..>>`) seen through several handles: the SPI
//! device, the control pin (CNV or LDAC) and the simulation's analog side. Time comes from a
//! shared [`MockClock`] advanced by [`MockDelay`] and by the simulation loop. Each bus runs
//! at a configured SCLK ([`BusClock`]) that the drivers set through
//! [`piezo_core::drivers::SpiClock`].

mod ad4020;
mod ad5791;

pub use ad4020::{
    AdcFault, AdcSpec, AdcStats, MockAdc, MockAdcSpi, MockCnv, DISCONNECTED_FRACTION,
};
pub use ad5791::{DacOutput, DacSpec, DacStats, MockDac, MockDacSpi, MockLdac};

use embedded_hal::delay::DelayNs;
use embedded_hal::digital;
use embedded_hal::spi;
use std::cell::Cell;
use std::rc::Rc;

/// Simulated time in nanoseconds, shared by the mocks.
#[derive(Debug, Clone, Default)]
pub struct MockClock(Rc<Cell<u64>>);

impl MockClock {
    #[inline]
    pub fn now_ns(&self) -> u64 {
        self.0.get()
    }
    #[inline]
    pub fn advance_ns(&self, ns: u64) {
        self.0.set(self.0.get().saturating_add(ns));
    }
    /// Moves the clock to `ns` if that is later.
    #[inline]
    pub fn set_ns(&self, ns: u64) {
        if ns > self.0.get() {
            self.0.set(ns);
        }
    }
}

/// `DelayNs` that advances the simulated clock instead of waiting.
#[derive(Debug, Clone)]
pub struct MockDelay(pub MockClock);

impl DelayNs for MockDelay {
    #[inline]
    fn delay_ns(&mut self, ns: u32) {
        self.0.advance_ns(ns as u64);
    }
}

/// A failed mock transaction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MockSpiError {
    /// An injected bus failure ([`MockAdc::fail_transactions`]).
    Injected,
    /// The frame broke a data-sheet rule (the chip's [`Violation`] says which).
    Violation(&'static str),
}

impl spi::Error for MockSpiError {
    fn kind(&self) -> spi::ErrorKind {
        spi::ErrorKind::Other
    }
}

/// A pin edge that broke a data-sheet rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MockPinError(pub &'static str);

impl digital::Error for MockPinError {
    fn kind(&self) -> digital::ErrorKind {
        digital::ErrorKind::Other
    }
}

/// A data-sheet rule a sequence broke: which, when, and the measured value it concerns
/// (ns or Hz, as the rule says).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Violation {
    pub rule: &'static str,
    pub at_ns: u64,
    pub measured: u64,
}

/// The broken rules of one chip: how many, and the first.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Violations {
    pub count: u64,
    pub first: Option<Violation>,
}

impl Violations {
    /// Records `rule` and returns it (for the error the caller gets).
    #[cold]
    fn record(&mut self, rule: &'static str, at_ns: u64, measured: u64) -> &'static str {
        self.count += 1;
        self.first.get_or_insert(Violation {
            rule,
            at_ns,
            measured,
        });
        rule
    }
}

/// The SCLK of a mock bus: the rate it runs at now and the fastest it can run (a board's
/// SPI kernel clock over its smallest divider).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusClock {
    pub hz: u32,
    pub max_hz: u32,
}

impl Default for BusClock {
    /// 25 MHz (the H743 board's SPI setup), at most 50 MHz (100 MHz kernel clock / 2).
    fn default() -> Self {
        Self {
            hz: 25_000_000,
            max_hz: 50_000_000,
        }
    }
}

impl BusClock {
    /// The fastest rate at most `max_hz` (any rate up to the bus maximum).
    fn set_max(&mut self, max_hz: u32) -> u32 {
        self.hz = max_hz.min(self.max_hz);
        self.hz
    }
}
