//! The plant: the simulated stage behind the mock converter chips.

use piezo_core::firmware::{
    Converters, SpiPair, SAMPLE_HZ, SPI_CENTER_UM, SPI_SPAN_UM, STAGE_POLE_PER_S,
};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};

/// The stage the converters see: CBW hysteresis (000 eq. 1-2) followed by a first-order
/// lag (mechanical bandwidth), driven by a 20-bit DAC code over 0..150 V and sampled as an
/// AD4020 code (two's complement, the full scale over [`SPI_SPAN_UM`]).
pub struct SimStage {
    model: Cbw<f32>,
    state: BwState<f32>,
    /// Lag factor per sample, `1 - exp(-2 pi f_c / f_s)`.
    lag: f32,
    y_um: f32,
    volts_per_code: f32,
    codes_per_um: f32,
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
        }
    }

    /// DAC code in, ADC code out (one sample).
    pub fn step(&mut self, dac_code: i32) -> i32 {
        let u = dac_code as f32 * self.volts_per_code;
        let y = self.model.step(&mut self.state, u, 1.0 / SAMPLE_HZ as f32);
        self.y_um += self.lag * (y - self.y_um);
        let half = (1i32 << (SpiPair::ADC_BITS - 1)) as f32;
        let centre = SPI_CENTER_UM as f32;
        let code = libm::floorf((self.y_um - centre) * self.codes_per_um + 0.5);
        if code >= half - 1.0 {
            half as i32 - 1
        } else if code >= -half {
            code as i32
        } else {
            -half as i32
        }
    }
}
