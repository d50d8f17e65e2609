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

/// The stage the converters see: CBW hysteresis (000 eq. 1-2) followed by a first-order
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
        let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("CBW parameter set 1 is valid");
        let lag = 1.0 - libm::expf(-(STAGE_POLE_PER_S as f32) / sample_hz);
        Self {
            model,
            state: model.init(0.0),
            lag,
            y_um: 0.0,
            volts_per_code: 150.0 / SpiPair::DAC_FULL as f32,
            codes_per_um: (1u32 << SpiPair::ADC_BITS) as f32 / SPI_SPAN_UM as f32,
            resonance: None,
            generation: 0,
        }
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
        let u = dac_code as f32 * self.volts_per_code;
        let y = self.model.step(&mut self.state, u, 1.0 / SAMPLE_HZ as f32);
        self.y_um += self.lag * (y - self.y_um);
        let y_um = match self.resonance.as_mut() {
            Some(r) => r.update(self.y_um),
            None => self.y_um,
        };
        let half = (1i32 << (SpiPair::ADC_BITS - 1)) as f32;
        let centre = SPI_CENTER_UM as f32;
        let code = libm::floorf((y_um - centre) * self.codes_per_um + 0.5);
        if code >= half - 1.0 {
            half as i32 - 1
        } else if code >= -half {
            code as i32
        } else {
            -half as i32
        }
    }
}
