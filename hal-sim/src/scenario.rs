//! Scenario files (TOML): the stage (which effects are on, their parameters), the
//! converters, the reference and the run length.
//!
//! Every section and field is optional; what is missing takes the default stage's value
//! (`Scenario::default()`). Unknown fields are errors, so a typo never goes unnoticed.
//! Example: see [`EXAMPLE`].

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

mod effects;
pub use effects::{AmplitudeDynamics, Backlash, RateHysteresis, SensorNonlinearity, StartupCreep};

/// A documented example scenario (parsed by a test).
pub const EXAMPLE: &str = r#"
name = "sine-50hz-creep"
[run]
duration_s = 0.2
loop_hz = 100000
substeps = 4
[reference]
wave = "sine"          # sine | triangle | steps | hold | raster | lissajous
freq_hz = 50.0
amplitude_um = 40.0
offset_um = 50.0
[stage.hysteresis]
model = "cbw"          # cbw | gbw | dahl | mbw002 | none
[stage.creep]
enabled = true
gains = [0.01, 0.01, 0.015]
taus_s = [0.01, 0.1, 1.0]
[stage.resonance]
freq_hz = 1500.0
zeta = 0.03
"#;

/// A complete scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    pub name: String,
    pub run: Run,
    pub reference: Reference,
    pub stage: StageConfig,
    pub converters: Converters,
    pub pipeline: PipelineLimits,
}

/// The firmware pipeline's output limits (piezo volts).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineLimits {
    pub volts_min: f64,
    pub volts_max: f64,
    pub slew_volts_per_s: f64,
    pub safe_volts: f64,
}

impl Default for PipelineLimits {
    fn default() -> Self {
        Self {
            volts_min: 0.0,
            volts_max: 150.0,
            slew_volts_per_s: 30_000.0,
            safe_volts: 0.0,
        }
    }
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            name: "default".into(),
            run: Run::default(),
            reference: Reference::default(),
            stage: StageConfig::default(),
            converters: Converters::default(),
            pipeline: PipelineLimits::default(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Run {
    /// Simulated time (s).
    pub duration_s: f64,
    /// Control loop rate (Hz).
    pub loop_hz: f64,
    /// Stage integration steps per loop sample.
    pub substeps: usize,
    /// Metrics ignore the first `settle_s` seconds (start-up transient).
    pub settle_s: Option<f64>,
    /// Seed of the noise generators.
    pub seed: u64,
}

impl Default for Run {
    fn default() -> Self {
        Self {
            duration_s: 0.3,
            loop_hz: 100_000.0,
            substeps: 1,
            settle_s: None,
            seed: 1,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WaveKind {
    Hold,
    Sine,
    Triangle,
    Steps,
    Raster,
    Lissajous,
}

/// The reference: one wave per axis (2-axis scans: raster, lissajous).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Reference {
    pub wave: WaveKind,
    /// Frequency (Hz); for raster the line rate, for lissajous the x frequency.
    pub freq_hz: f64,
    /// Peak amplitude (um) around `offset_um`; for steps the half span.
    pub amplitude_um: f64,
    /// Centre (um).
    pub offset_um: f64,
    /// Steps: number of levels.
    pub levels: u16,
    /// Raster: frame rate; lissajous: y frequency (Hz).
    pub freq2_hz: f64,
}

impl Default for Reference {
    fn default() -> Self {
        Self {
            wave: WaveKind::Sine,
            freq_hz: 10.0,
            amplitude_um: 40.0,
            // Centre of the default stage's major loop (about 16-118 um over 0-150 V).
            offset_um: 65.0,
            levels: 5,
            freq2_hz: 3.0,
        }
    }
}

/// The simulated actuator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StageConfig {
    /// Number of axes (1..=3).
    pub axes: usize,
    /// Position of the relaxed stage at 0 V (um): where the sensor's zero is. With 0 the
    /// major loop over 0-150 V spans about 16-118 um (remanent displacement after a descent
    /// to 0 V, creep); -16.5 puts it at 0-100 um (the model-based compensators do not know
    /// this offset).
    pub zero_um: f64,
    pub amplifier: Amplifier,
    pub hysteresis: HysteresisCfg,
    pub creep: Creep,
    pub resonance: Resonance,
    pub drift: Drift,
    pub noise: Noise,
    pub force: Force,
    pub delay: Delay,
    pub coupling: Coupling,
    /// What real stages do besides (all off by default; [`effects`]).
    pub rate_hysteresis: RateHysteresis,
    pub backlash: Backlash,
    pub startup_creep: StartupCreep,
    pub amplitude_dynamics: AmplitudeDynamics,
    pub sensor_nonlinearity: SensorNonlinearity,
    /// An identified model (`piezo sim --stage fit.json`) in place of hysteresis, creep
    /// and structure.
    pub identified: Option<crate::stage::identified::IdentifiedCfg>,
}

impl Default for StageConfig {
    fn default() -> Self {
        Self {
            axes: 1,
            zero_um: 0.0,
            amplifier: Amplifier::default(),
            hysteresis: HysteresisCfg::default(),
            creep: Creep::default(),
            resonance: Resonance::default(),
            drift: Drift::default(),
            noise: Noise::default(),
            force: Force::default(),
            delay: Delay::default(),
            coupling: Coupling::default(),
            rate_hysteresis: RateHysteresis::default(),
            backlash: Backlash::default(),
            startup_creep: StartupCreep::default(),
            amplitude_dynamics: AmplitudeDynamics::default(),
            sensor_nonlinearity: SensorNonlinearity::default(),
            identified: None,
        }
    }
}

/// High-voltage amplifier: `v' = (gain*v_dac + offset - v) * 2 pi bandwidth`, rate limited by
/// `current_limit_a / capacitance_f`, clipped at the rails.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Amplifier {
    pub gain: f64,
    pub offset_volts: f64,
    pub rail_min_volts: f64,
    pub rail_max_volts: f64,
    pub bandwidth_hz: f64,
    pub current_limit_a: f64,
    /// Piezo capacitance (F).
    pub capacitance_f: f64,
}

impl Default for Amplifier {
    fn default() -> Self {
        Self {
            gain: 15.0,
            offset_volts: 0.0,
            rail_min_volts: -20.0,
            rail_max_volts: 170.0,
            bandwidth_hz: 5_000.0,
            current_limit_a: 0.06,
            capacitance_f: 1.5e-6,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HysteresisModel {
    /// No hysteresis: `y = d*u`.
    None,
    Cbw,
    Gbw,
    Dahl,
    /// The modified Bouc-Wen of 002 (eq. 4-5): ABW with `delta*|u'|` plus `p*u' + q*u'^3`.
    Mbw002,
}

/// Static part of the Hammerstein chain: `y = model(u) + asym_um_per_v2 * u^2`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HysteresisCfg {
    pub model: HysteresisModel,
    /// Piezo coefficient (um/V).
    pub d: f64,
    /// CBW/GBW `alpha`, Dahl `sigma0` (um/V).
    pub alpha: f64,
    /// CBW `beta`; GBW `B` (the `B*sgn(u')` asymmetry term of 000 eq. 3).
    pub beta: f64,
    /// CBW `gamma`; GBW `G`.
    pub gamma: f64,
    /// GBW `A`.
    pub a: f64,
    /// GBW `B_h`, the CBW term `B_h*sgn(u'*h)` (0: eq. 3 as printed, whose loop does not
    /// last; see `piezo_core::hysteresis::Gbw`).
    pub beta_h: f64,
    /// 002 MBW (piezo form): asymmetry `delta` of `delta*|u'|` (um/V), rate terms `p`
    /// (um s/V) and `q` (um s^3/V^3) of `p*u' + q*u'^3`; `alpha, beta, gamma` as CBW.
    pub delta: f64,
    pub p: f64,
    pub q: f64,
    /// Bouc-Wen exponent `n`; Dahl exponent `i`.
    pub n: f64,
    /// Dahl saturation `hc` (um).
    pub hc: f64,
    /// Asymmetric static term (um/V^2).
    pub asym_um_per_v2: f64,
    /// Parameter error of the models the controllers are built with: they see `alpha, beta,
    /// gamma` (Dahl: `sigma0`) times `1 + model_error` (e.g. +-0.2 for +-20 %); the stage
    /// runs the values above.
    pub model_error: f64,
}

impl Default for HysteresisCfg {
    fn default() -> Self {
        Self {
            model: HysteresisModel::Cbw,
            d: 0.93,
            alpha: 0.3,
            beta: 0.012,
            gamma: 0.004,
            a: 1.0,
            beta_h: 0.0,
            delta: 0.0,
            p: 0.0,
            q: 0.0,
            n: 1.0,
            hc: 15.0,
            asym_um_per_v2: -4.0e-4,
            model_error: 0.0,
        }
    }
}

/// Creep: first-order elements in parallel, `c_i' = (gain_i*y - c_i)/tau_i`, added to `y`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Creep {
    pub enabled: bool,
    pub gains: Vec<f64>,
    pub taus_s: Vec<f64>,
}

impl Default for Creep {
    fn default() -> Self {
        Self {
            enabled: true,
            gains: vec![0.01, 0.015, 0.02],
            taus_s: vec![0.02, 0.3, 5.0],
        }
    }
}

/// Structural dynamics: `x'' + 2 zeta w x' + w^2 x = w^2 (y + F/k)`, unit DC gain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Resonance {
    pub enabled: bool,
    pub freq_hz: f64,
    pub zeta: f64,
}

impl Default for Resonance {
    fn default() -> Self {
        Self {
            enabled: true,
            freq_hz: 1_500.0,
            zeta: 0.03,
        }
    }
}

/// Thermal drift: `um * (1 - exp(-t/tau_s))` plus `rate_um_per_s * t`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Drift {
    pub enabled: bool,
    pub um: f64,
    pub tau_s: f64,
    pub rate_um_per_s: f64,
}

impl Default for Drift {
    fn default() -> Self {
        Self {
            enabled: true,
            um: 0.5,
            tau_s: 2.0,
            rate_um_per_s: 0.0,
        }
    }
}

/// White position-sensor noise (um RMS).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Noise {
    pub enabled: bool,
    pub sigma_um: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Self {
            enabled: true,
            sigma_um: 0.005,
        }
    }
}

/// External force on the stage: a step of `newtons` at `at_s` (or a sine of `freq_hz`
/// if it is > 0), acting through the stiffness.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Force {
    pub enabled: bool,
    pub newtons: f64,
    pub stiffness_n_per_um: f64,
    pub at_s: f64,
    pub freq_hz: f64,
}

impl Default for Force {
    fn default() -> Self {
        Self {
            enabled: false,
            newtons: 5.0,
            stiffness_n_per_um: 1.0,
            at_s: 0.1,
            freq_hz: 0.0,
        }
    }
}

/// Pure delay of the position measurement (s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Delay {
    pub enabled: bool,
    pub seconds: f64,
}

impl Default for Delay {
    fn default() -> Self {
        Self {
            enabled: true,
            seconds: 5e-6,
        }
    }
}

/// Cross-coupling: `y_i += sum_j matrix[i][j] * y_j` (j != i) before the structure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Coupling {
    pub enabled: bool,
    pub matrix: Vec<Vec<f64>>,
}

impl Default for Coupling {
    fn default() -> Self {
        Self {
            enabled: false,
            matrix: vec![vec![0.0, 0.04], vec![0.03, 0.0]],
        }
    }
}

/// The converters and the sensor front end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Converters {
    /// Sensor front end: `volts = (y - sensor_center_um) * sensor_volts_per_um`.
    pub sensor_volts_per_um: f64,
    pub sensor_center_um: f64,
    /// ADC resolution (16, 18 or 20 bits), reference (V), errors.
    pub adc_bits: u32,
    pub adc_vref: f64,
    pub adc_offset_lsb: f64,
    pub adc_gain_error: f64,
    pub adc_noise_lsb: f64,
    /// DAC: 20 bits, output range `[dac_vrefn, dac_vrefp]` (V) into the amplifier, errors.
    pub dac_vrefp: f64,
    pub dac_vrefn: f64,
    pub dac_offset_lsb: f64,
    pub dac_gain_error: f64,
}

impl Default for Converters {
    fn default() -> Self {
        Self {
            sensor_volts_per_um: 0.07,
            sensor_center_um: 50.0,
            adc_bits: 20,
            adc_vref: 5.0,
            adc_offset_lsb: 3.0,
            adc_gain_error: 1e-4,
            adc_noise_lsb: 1.0,
            dac_vrefp: 10.0,
            dac_vrefn: 0.0,
            dac_offset_lsb: 2.0,
            dac_gain_error: -1e-4,
        }
    }
}

fn positive(v: f64, field: &str) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{field} must be finite and > 0, got {v}");
    }
    Ok(())
}

fn finite(v: f64, field: &str) -> Result<()> {
    if !v.is_finite() {
        bail!("{field} must be finite, got {v}");
    }
    Ok(())
}

impl Scenario {
    /// Parses and validates a TOML scenario.
    pub fn from_toml(text: &str) -> Result<Self> {
        let s: Scenario = toml::from_str(text)?;
        s.validate()?;
        Ok(s)
    }

    /// Reads a scenario file; the error names the file and the field.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scenario {}", path.display()))?;
        Self::from_toml(&text).with_context(|| format!("bad scenario {}", path.display()))
    }

    /// The run's settling time: the given one, or one reference period (at most half the run).
    pub fn settle_s(&self) -> f64 {
        self.run.settle_s.unwrap_or_else(|| {
            let f = self.reference.freq_hz.min(if self.is_scan() {
                self.reference.freq2_hz
            } else {
                f64::INFINITY
            });
            let period = if f > 0.0 { 1.0 / f } else { 0.0 };
            period.min(0.5 * self.run.duration_s)
        })
    }

    /// A 2-axis scan reference.
    pub fn is_scan(&self) -> bool {
        matches!(self.reference.wave, WaveKind::Raster | WaveKind::Lissajous)
    }

    /// Checks every value; errors name the field.
    pub fn validate(&self) -> Result<()> {
        let r = &self.run;
        positive(r.duration_s, "run.duration_s")?;
        positive(r.loop_hz, "run.loop_hz")?;
        if r.duration_s * r.loop_hz > 1e9 {
            bail!("run.duration_s * run.loop_hz: more than 1e9 samples");
        }
        if !(1..=64).contains(&r.substeps) {
            bail!("run.substeps must be in 1..=64, got {}", r.substeps);
        }
        if let Some(s) = r.settle_s {
            if !(s.is_finite() && s >= 0.0 && s < r.duration_s) {
                bail!("run.settle_s must be in [0, run.duration_s), got {s}");
            }
        }
        let f = &self.reference;
        if !(f.freq_hz.is_finite() && f.freq_hz >= 0.0 && f.freq_hz < r.loop_hz / 2.0) {
            bail!(
                "reference.freq_hz must be in [0, loop_hz/2), got {}",
                f.freq_hz
            );
        }
        if !(f.freq2_hz.is_finite() && f.freq2_hz >= 0.0 && f.freq2_hz < r.loop_hz / 2.0) {
            bail!(
                "reference.freq2_hz must be in [0, loop_hz/2), got {}",
                f.freq2_hz
            );
        }
        finite(f.amplitude_um, "reference.amplitude_um")?;
        finite(f.offset_um, "reference.offset_um")?;
        if f.wave == WaveKind::Steps && f.levels < 2 {
            bail!("reference.levels must be >= 2 for steps");
        }
        let st = &self.stage;
        if !(1..=3).contains(&st.axes) {
            bail!("stage.axes must be 1, 2 or 3, got {}", st.axes);
        }
        if self.is_scan() && st.axes != 2 {
            bail!("reference.wave = raster/lissajous needs stage.axes = 2");
        }
        finite(st.zero_um, "stage.zero_um")?;
        let a = &st.amplifier;
        positive(a.gain, "stage.amplifier.gain")?;
        finite(a.offset_volts, "stage.amplifier.offset_volts")?;
        finite(a.rail_min_volts, "stage.amplifier.rail_min_volts")?;
        finite(a.rail_max_volts, "stage.amplifier.rail_max_volts")?;
        if a.rail_min_volts >= a.rail_max_volts {
            bail!("stage.amplifier.rail_min_volts must be below rail_max_volts");
        }
        positive(a.bandwidth_hz, "stage.amplifier.bandwidth_hz")?;
        positive(a.current_limit_a, "stage.amplifier.current_limit_a")?;
        positive(a.capacitance_f, "stage.amplifier.capacitance_f")?;
        let h = &st.hysteresis;
        for (v, n) in [
            (h.d, "d"),
            (h.alpha, "alpha"),
            (h.beta, "beta"),
            (h.gamma, "gamma"),
            (h.a, "a"),
            (h.beta_h, "beta_h"),
            (h.delta, "delta"),
            (h.p, "p"),
            (h.q, "q"),
            (h.n, "n"),
            (h.hc, "hc"),
            (h.asym_um_per_v2, "asym_um_per_v2"),
        ] {
            finite(v, &format!("stage.hysteresis.{n}"))?;
        }
        positive(h.d, "stage.hysteresis.d")?;
        if !(h.model_error.is_finite() && h.model_error > -1.0) {
            bail!(
                "stage.hysteresis.model_error must be finite and > -1, got {}",
                h.model_error
            );
        }
        let c = &st.creep;
        if c.gains.len() != c.taus_s.len() {
            bail!("stage.creep.gains and stage.creep.taus_s must have the same length");
        }
        if c.gains.len() > 8 {
            bail!("stage.creep: at most 8 elements");
        }
        for (i, (&g, &t)) in c.gains.iter().zip(&c.taus_s).enumerate() {
            finite(g, &format!("stage.creep.gains[{i}]"))?;
            positive(t, &format!("stage.creep.taus_s[{i}]"))?;
        }
        let m = &st.resonance;
        positive(m.freq_hz, "stage.resonance.freq_hz")?;
        if !(m.zeta.is_finite() && m.zeta > 0.0 && m.zeta < 1.0) {
            bail!("stage.resonance.zeta must be in (0, 1), got {}", m.zeta);
        }
        if m.enabled && m.freq_hz * 2.0 * std::f64::consts::PI >= r.loop_hz * r.substeps as f64 {
            bail!("stage.resonance.freq_hz too high for run.loop_hz * run.substeps");
        }
        finite(st.drift.um, "stage.drift.um")?;
        positive(st.drift.tau_s, "stage.drift.tau_s")?;
        finite(st.drift.rate_um_per_s, "stage.drift.rate_um_per_s")?;
        if !(st.noise.sigma_um.is_finite() && st.noise.sigma_um >= 0.0) {
            bail!("stage.noise.sigma_um must be finite and >= 0");
        }
        finite(st.force.newtons, "stage.force.newtons")?;
        positive(
            st.force.stiffness_n_per_um,
            "stage.force.stiffness_n_per_um",
        )?;
        finite(st.force.at_s, "stage.force.at_s")?;
        if !(st.force.freq_hz.is_finite() && st.force.freq_hz >= 0.0) {
            bail!("stage.force.freq_hz must be finite and >= 0");
        }
        if !(st.delay.seconds.is_finite() && st.delay.seconds >= 0.0 && st.delay.seconds <= 0.01) {
            bail!("stage.delay.seconds must be in [0, 0.01]");
        }
        if st.coupling.enabled {
            let mm = &st.coupling.matrix;
            if mm.len() != st.axes || mm.iter().any(|row| row.len() != st.axes) {
                bail!(
                    "stage.coupling.matrix must be {0}x{0} (stage.axes = {0})",
                    st.axes
                );
            }
            if mm.iter().flatten().any(|v| !v.is_finite()) {
                bail!("stage.coupling.matrix: every entry must be finite");
            }
        }
        st.validate_effects()?;
        let cv = &self.converters;
        finite(cv.sensor_volts_per_um, "converters.sensor_volts_per_um")?;
        if cv.sensor_volts_per_um == 0.0 {
            bail!("converters.sensor_volts_per_um must be non-zero");
        }
        finite(cv.sensor_center_um, "converters.sensor_center_um")?;
        if ![16, 18, 20].contains(&cv.adc_bits) {
            bail!(
                "converters.adc_bits must be 16, 18 or 20, got {}",
                cv.adc_bits
            );
        }
        positive(cv.adc_vref, "converters.adc_vref")?;
        finite(cv.adc_offset_lsb, "converters.adc_offset_lsb")?;
        finite(cv.adc_gain_error, "converters.adc_gain_error")?;
        if !(cv.adc_noise_lsb.is_finite() && cv.adc_noise_lsb >= 0.0) {
            bail!("converters.adc_noise_lsb must be finite and >= 0");
        }
        finite(cv.dac_vrefp, "converters.dac_vrefp")?;
        finite(cv.dac_vrefn, "converters.dac_vrefn")?;
        if cv.dac_vrefn >= cv.dac_vrefp {
            bail!("converters.dac_vrefn must be below converters.dac_vrefp");
        }
        finite(cv.dac_offset_lsb, "converters.dac_offset_lsb")?;
        let p = &self.pipeline;
        finite(p.volts_min, "pipeline.volts_min")?;
        finite(p.volts_max, "pipeline.volts_max")?;
        if p.volts_min >= p.volts_max {
            bail!("pipeline.volts_min must be below pipeline.volts_max");
        }
        positive(p.slew_volts_per_s, "pipeline.slew_volts_per_s")?;
        if !(p.safe_volts >= p.volts_min && p.safe_volts <= p.volts_max) {
            bail!("pipeline.safe_volts must lie in [volts_min, volts_max]");
        }
        finite(cv.dac_gain_error, "converters.dac_gain_error")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_parses_and_defaults_fill_in() {
        let s = Scenario::from_toml(EXAMPLE).unwrap();
        assert_eq!(s.name, "sine-50hz-creep");
        assert_eq!(s.reference.freq_hz, 50.0);
        assert_eq!(s.stage.amplifier, Amplifier::default());
        assert!(Scenario::from_toml("").is_ok());
    }

    #[test]
    fn errors_name_the_field() {
        let e = Scenario::from_toml("[stage.resonance]\nzeta = 2.0").unwrap_err();
        assert!(format!("{e:#}").contains("stage.resonance.zeta"), "{e:#}");
        let e = Scenario::from_toml("[stage.creep]\ngians = [1.0]").unwrap_err();
        assert!(format!("{e:#}").contains("gians"), "{e:#}");
        let e = Scenario::from_toml("[run]\nloop_hz = \"fast\"").unwrap_err();
        assert!(format!("{e:#}").contains("loop_hz"), "{e:#}");
        let e =
            Scenario::from_toml("[stage]\naxes = 1\n[reference]\nwave = \"raster\"").unwrap_err();
        assert!(format!("{e:#}").contains("stage.axes"), "{e:#}");
    }
}
