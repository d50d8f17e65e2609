//! The plant: the simulated stage behind the mock converter chips.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};
use piezo_core::feedback::Biquad;
use piezo_core::firmware::{
    Converters, SpiPair, SAMPLE_HZ, SPI_CENTER_UM, SPI_SPAN_UM, STAGE_POLE_PER_S,
};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};

/// The stage's mechanical resonance, as the harness line `resonance <hz> <zeta>` sets it
/// (f32 bits; 0 Hz: none, the default, so every other test runs the stage of before).
/// [`RESONANCE_GEN`] counts the changes; each stage rebuilds its filter when it moves.
pub static RESONANCE_HZ: AtomicU32 = AtomicU32::new(0);
pub static RESONANCE_ZETA: AtomicU32 = AtomicU32::new(0);
pub static RESONANCE_GEN: AtomicU32 = AtomicU32::new(0);

/// The stage's own parameters against the firmware's built-in model, as the harness line
/// `stage <gain> <hysteresis> <creep>` sets them (f32 bits of the three scales, each
/// checked against [`STAGE_RANGES`] first): `gain` scales the whole output (`d` and `alpha`
/// of the CBW), `hysteresis` the loop width on top of it (`alpha` alone), `creep` the gains
/// of the creep elements [`CREEP_GAINS`]. At power-up 1, 1, 0: the CBW of the firmware's
/// defaults and no creep, so every other test runs the stage of before. [`STAGE_GEN`]
/// counts the changes; each stage rebuilds its model when it moves.
pub static STAGE_GAIN: AtomicU32 = AtomicU32::new(0x3f80_0000);
pub static STAGE_HYSTERESIS: AtomicU32 = AtomicU32::new(0x3f80_0000);
pub static STAGE_CREEP: AtomicU32 = AtomicU32::new(0);
pub static STAGE_GEN: AtomicU32 = AtomicU32::new(0);

/// Allowed `stage` scales (inclusive): gain 0.5..2 (the stroke from 12 to 48 um over
/// 0..150 V), hysteresis 0.25..3 (`alpha` 0.0175..0.21 um/V at gain 1; the CBW stays valid,
/// `beta - gamma >= 0` is untouched), creep 0..4.
pub const STAGE_RANGES: [(f32, f32); 3] = [(0.5, 2.0), (0.25, 3.0), (0.0, 4.0)];

/// Creep of the stage at `creep` 1: first-order elements in parallel on the hysteresis
/// output `y_s`, `c_i' = (g_i y_s - c_i) / tau_i`, `y = y_s + sum c_i` (the form of
/// hal-sim's stage and of the core's `CreepInverse`), with the time constants
/// [`CREEP_TAUS_S`]: a held voltage creeps 6 % further at `creep` 1, two thirds of it
/// within 0.1 s. Real creep runs over seconds to hours; these constants are short so that
/// the emulator, which runs the loop in virtual time far slower than real time, shows it
/// within the records a CI run can afford.
pub const CREEP_GAINS: [f32; 2] = [0.02, 0.04];
pub const CREEP_TAUS_S: [f32; 2] = [0.01, 0.1];

/// The three `stage` scales if each is within [`STAGE_RANGES`] (finite), else `None`.
pub fn checked_stage(gain: f32, hysteresis: f32, creep: f32) -> Option<[f32; 3]> {
    let v = [gain, hysteresis, creep];
    v.iter()
        .zip(STAGE_RANGES)
        .all(|(x, (lo, hi))| x.is_finite() && *x >= lo && *x <= hi)
        .then_some(v)
}

/// The stage the converters see: CBW hysteresis (000 eq. 1-2), creep (none unless the
/// harness line `stage` sets it, [`CREEP_GAINS`]), a first-order
/// lag (mechanical bandwidth) and, when the harness sets one, a lightly damped second-order
/// mode `w^2 / (s^2 + 2 zeta w s + w^2)` (unity DC gain), driven by a 20-bit DAC code over
/// 0..150 V and sampled as an AD4020 code (two's complement, the full scale over
/// [`SPI_SPAN_UM`]).
pub struct SimStage {
    model: Cbw<f32>,
    state: BwState<f32>,
    /// Lag factor per sample, `1 - exp(-2 pi f_c / f_s)`.
    lag: f32,
    y_um: f32,
    volts_per_code: f32,
    codes_per_um: f32,
    resonance: Option<Biquad<f32>>,
    /// [`RESONANCE_GEN`] of `resonance`.
    generation: u32,
    /// Creep elements: per-sample decay `exp(-dt/tau_i)`, gains `g_i` (scaled), states.
    creep_decay: [f32; 2],
    creep_gain: [f32; 2],
    creep: [f32; 2],
    /// [`STAGE_GEN`] of `model` and `creep_gain`.
    stage_generation: u32,
    /// The sensor's noise: xorshift32 state.
    noise: u32,
}

/// The CBW of the firmware's defaults (000 backup slide parameter set 1) with the `stage`
/// scales: `d` times `gain`, `alpha` times `gain * hysteresis`.
fn scaled_model(gain: f32, hysteresis: f32) -> Option<Cbw<f32>> {
    Cbw::with_n1(0.16 * gain, 0.07 * gain * hysteresis, 0.02, 0.01).ok()
}

/// The mode `w^2 / (s^2 + 2 zeta w s + w^2)` by the bilinear transform prewarped at `hz`
/// (its undamped frequency stays exact), settled at `y_um`. `None` for 0 Hz or parameters
/// out of range (above 0.45 of the sample rate, `zeta` outside (0, 1]).
pub fn resonance(hz: f32, zeta: f32, sample_hz: f32, y_um: f32) -> Option<Biquad<f32>> {
    if !(hz > 0.0 && hz < 0.45 * sample_hz && zeta > 0.0 && zeta <= 1.0) {
        return None;
    }
    let w = 2.0 * core::f32::consts::PI * hz;
    let k = w / libm::tanf(w / (2.0 * sample_hz));
    let (w2, k2) = (w * w, k * k);
    let d = k2 + 2.0 * zeta * w * k + w2;
    let b = [w2 / d, 2.0 * w2 / d, w2 / d];
    let a = [
        (2.0 * w2 - 2.0 * k2) / d,
        (k2 - 2.0 * zeta * w * k + w2) / d,
    ];
    let mut f = Biquad::new(b, a).ok()?;
    f.settle(y_um);
    Some(f)
}

impl SimStage {
    /// 000 backup slide parameter set 1, lag pole [`STAGE_POLE_PER_S`].
    pub fn new(sample_hz: f32) -> Self {
        let model = scaled_model(1.0, 1.0).expect("CBW parameter set 1 is valid");
        let lag = 1.0 - libm::expf(-(STAGE_POLE_PER_S as f32) / sample_hz);
        Self {
            creep_decay: CREEP_TAUS_S.map(|tau| libm::expf(-1.0 / (tau * sample_hz))),
            creep_gain: [0.0; 2],
            creep: [0.0; 2],
            stage_generation: 0,
            model,
            state: model.init(0.0),
            lag,
            y_um: 0.0,
            volts_per_code: 150.0 / SpiPair::DAC_FULL as f32,
            codes_per_um: (1u32 << SpiPair::ADC_BITS) as f32 / SPI_SPAN_UM as f32,
            resonance: None,
            generation: 0,
            noise: 0x2545_f491,
        }
    }

    /// The position sensor's noise (LSB): -3..=3, triangular, mean 0, 1.6 LSB rms (0.2 nm at
    /// 20 bits over 120 um; a real sensor and the AD4020 never hold one code for long).
    fn noise_lsb(&mut self) -> f32 {
        let mut x = self.noise;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.noise = x;
        ((x >> 30) as i32 - ((x >> 28) & 3) as i32) as f32
    }

    /// DAC code in, ADC code out (one sample).
    pub fn step(&mut self, dac_code: i32) -> i32 {
        let generation = RESONANCE_GEN.load(Relaxed);
        if generation != self.generation {
            self.generation = generation;
            let hz = f32::from_bits(RESONANCE_HZ.load(Relaxed));
            let zeta = f32::from_bits(RESONANCE_ZETA.load(Relaxed));
            self.resonance = resonance(hz, zeta, SAMPLE_HZ as f32, self.y_um);
        }
        let stage_generation = STAGE_GEN.load(Relaxed);
        if stage_generation != self.stage_generation {
            self.stage_generation = stage_generation;
            let [gain, hysteresis, creep] = [&STAGE_GAIN, &STAGE_HYSTERESIS, &STAGE_CREEP]
                .map(|a| f32::from_bits(a.load(Relaxed)));
            // The harness checked the scales ([`checked_stage`]); the state carries on.
            if let Some(m) = scaled_model(gain, hysteresis) {
                self.model = m;
            }
            self.creep_gain = CREEP_GAINS.map(|g| g * creep);
        }
        let u = dac_code as f32 * self.volts_per_code;
        let y_s = self.model.step(&mut self.state, u, 1.0 / SAMPLE_HZ as f32);
        let mut y = y_s;
        for ((c, e), g) in self
            .creep
            .iter_mut()
            .zip(self.creep_decay)
            .zip(self.creep_gain)
        {
            *c = e * *c + (1.0 - e) * g * y_s;
            y += *c;
        }
        self.y_um += self.lag * (y - self.y_um);
        let y_um = match self.resonance.as_mut() {
            Some(r) => r.update(self.y_um),
            None => self.y_um,
        };
        let half = (1i32 << (SpiPair::ADC_BITS - 1)) as f32;
        let centre = SPI_CENTER_UM as f32;
        let code = libm::floorf((y_um - centre) * self.codes_per_um + 0.5) + self.noise_lsb();
        if code >= half - 1.0 {
            half as i32 - 1
        } else if code >= -half {
            code as i32
        } else {
            -half as i32
        }
    }
}
