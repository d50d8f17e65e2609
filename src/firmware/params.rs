//! What `set` changes besides the limits: the hysteresis model, the open-loop scaling and
//! the gains the laws and compensators are built from.

use super::target::{c, R};
use crate::command::Error;
use crate::feedback::Biquad;
use crate::feedforward::LinearFf;
use crate::hysteresis::{Cbw, Gbw};

/// Lowest notch centre (Hz) other than 0 (off).
pub const NOTCH_HZ_MIN: f64 = 10.0;
/// Highest notch centre as a fraction of the Nyquist rate (0.9: 45 kHz at 100 kHz, 7373 Hz
/// at the Q16.16 build's 16 384 Hz).
pub const NOTCH_NYQUIST_FRACTION: f64 = 0.9;
/// Range of the notch's quality factor.
pub const NOTCH_Q: (f64, f64) = (0.5, 50.0);

/// What `set` changes besides the limits: the hysteresis model (the one `piezo fit
/// --model cbw` identifies), the open-loop scaling and the gains (config, apart from the
/// laws' state). [`Params::default`] is the simulated stage: CBW set 1 of the 000 backup
/// slide, first-order linear part with pole [`super::STAGE_POLE_PER_S`]; `Default` and the
/// slots by name are the settings table's (`settings.rs`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// CBW (n = 1) of the IMS feedforward and the HGO's observer model: `d`, `alpha` (um/V),
    /// `beta`, `gamma` (1/V).
    pub cbw_d: R,
    pub cbw_alpha: R,
    pub cbw_beta: R,
    pub cbw_gamma: R,
    /// Asymmetry `B` (1/V) of the GBW of `fts-gbw` and `nmpc-gbw` ([`Params::gbw_model`]).
    pub gbw_b: R,
    /// Open-loop scaling (open-loop mode and the `linear` compensator).
    pub um_per_volt: R,
    pub offset_um: R,
    /// HGO `epsilon` (s), 000 eq. (8).
    pub hgo_eps_s: R,
    /// Robust law gains (1/s).
    pub lambda1: R,
    pub lambda2: R,
    /// PID gains: V/um and V/(um s).
    pub pid_kp: R,
    pub pid_ki: R,
    /// Notch on the measured position of every feedback law ([`Params::notch`]): centre
    /// (Hz, 0 = off) and quality factor (centre over -3 dB bandwidth).
    pub notch_hz: R,
    pub notch_q: R,
}

impl Params {
    pub fn model(&self) -> Option<Cbw<R>> {
        Cbw::with_n1(self.cbw_d, self.cbw_alpha, self.cbw_beta, self.cbw_gamma).ok()
    }

    /// The GBW (000 eq. 3 with its CBW term, [`Gbw::with_beta_h`]) that nests the CBW
    /// (`alpha = n = 1`, `A, B_h, G` = the CBW's `alpha, beta, gamma`) with the asymmetry
    /// `B = gbw_b`; `gbw_b = 0` is the CBW's own loop.
    pub fn gbw_model(&self) -> Option<Gbw<R>> {
        let one = c(1.0);
        Gbw::with_beta_h(
            self.cbw_d,
            one,
            self.cbw_alpha,
            self.cbw_beta,
            self.gbw_b,
            self.cbw_gamma,
            one,
        )
        .ok()
    }

    pub fn linear(&self) -> LinearFf<R> {
        LinearFf {
            um_per_volt: self.um_per_volt,
            offset_um: self.offset_um,
        }
    }

    /// The notch of [`Params::notch_hz`] and [`Params::notch_q`] at `sample_hz`: `Ok(None)`
    /// when `notch_hz` is 0 (off), `Err` outside [`NOTCH_HZ_MIN`] ..= [`NOTCH_NYQUIST_FRACTION`]
    /// of the Nyquist rate or `notch_q` outside [`NOTCH_Q`] (or a biquad the number type
    /// cannot hold stable): [`Error::OutOfRange`].
    pub fn notch(&self, sample_hz: R) -> Result<Option<Biquad<R>>, Error> {
        if self.notch_hz == c(0.0) {
            // Off; `notch_q` still has to be in range (it is stored and applies later).
            return if (c(NOTCH_Q.0)..=c(NOTCH_Q.1)).contains(&self.notch_q) {
                Ok(None)
            } else {
                Err(Error::OutOfRange)
            };
        }
        let top = sample_hz * c(0.5 * NOTCH_NYQUIST_FRACTION);
        let ok = self.notch_hz >= c(NOTCH_HZ_MIN)
            && self.notch_hz <= top
            && (c(NOTCH_Q.0)..=c(NOTCH_Q.1)).contains(&self.notch_q);
        if !ok {
            return Err(Error::OutOfRange);
        }
        Biquad::notch(self.notch_hz, self.notch_q, sample_hz)
            .map(Some)
            .map_err(|_| Error::OutOfRange)
    }
}
