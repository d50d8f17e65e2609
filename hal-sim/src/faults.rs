//! Fault campaign over every controller mode (`piezo faults`).
//!
//! Each case runs the firmware pipeline on the simulated stage with one fault injected at a
//! random sample, for a random duration and size (seeded). What is counted:
//! * **unsafe outputs**: a DAC code outside the configured voltage range, or a change
//!   between two consecutive DAC codes above the slew limit, at the converter itself
//!   (checked on every sample, whatever the pipeline believes it wrote);
//! * **samples to safe**: for faults the pipeline can detect (sensor out of range, failed
//!   conversion, failed DAC write), samples from the fault reaching the pipeline to the
//!   pipeline commanding its safe voltage (0 = the same sample);
//! * **recorder samples lost**: a capture armed before the fault; every frame the control
//!   task pushed must come back bit for bit from the finished capture.

use anyhow::{anyhow, Result};
use piezo_core::recorder::{ArrayRecorder, Signal, Trigger};
use rayon::prelude::*;
use serde::Serialize;

use crate::numeric::Rng;
use crate::scenario::Scenario;
use crate::sim::controllers::{registry, Entry, R};
use crate::sim::{calibrate, Bench, Inject, StageInfo};

/// Every fault of the campaign.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// The ADC returns the same code for a while.
    SensorStuck,
    /// Codes outside the sensor's valid window.
    SensorOutOfRange,
    /// The conversion fails (bus error, NaN/inf from a converter): no valid code.
    ConversionFailed,
    /// Noise 100x the nominal sensor noise.
    NoiseBurst,
    /// Samples that never reach the control task.
    DroppedSamples,
    /// The same ADC sample delivered twice.
    DuplicatedSamples,
    /// The DAC does not take the code.
    DacWriteFailed,
    /// The amplifier rails are lower than the commanded voltages.
    AmplifierSaturation,
    /// The stage's hysteresis parameters +-20 % off the controller's.
    ParameterDrift,
    /// An external load step of 37 % of the stroke.
    StepLoad,
    /// Control steps that miss their deadline: every other period is lost.
    Overrun,
}

impl FaultKind {
    pub const ALL: [FaultKind; 11] = [
        FaultKind::SensorStuck,
        FaultKind::SensorOutOfRange,
        FaultKind::ConversionFailed,
        FaultKind::NoiseBurst,
        FaultKind::DroppedSamples,
        FaultKind::DuplicatedSamples,
        FaultKind::DacWriteFailed,
        FaultKind::AmplifierSaturation,
        FaultKind::ParameterDrift,
        FaultKind::StepLoad,
        FaultKind::Overrun,
    ];

    pub fn name(self) -> &'static str {
        match self {
            FaultKind::SensorStuck => "sensor-stuck",
            FaultKind::SensorOutOfRange => "sensor-out-of-range",
            FaultKind::ConversionFailed => "conversion-nan",
            FaultKind::NoiseBurst => "noise-burst-100x",
            FaultKind::DroppedSamples => "dropped-samples",
            FaultKind::DuplicatedSamples => "duplicated-samples",
            FaultKind::DacWriteFailed => "dac-write-failed",
            FaultKind::AmplifierSaturation => "amplifier-saturation",
            FaultKind::ParameterDrift => "parameter-drift-20pct",
            FaultKind::StepLoad => "step-load-37pct",
            FaultKind::Overrun => "control-overrun",
        }
    }

    /// Faults the pipeline can see and must answer with its safe state.
    pub fn detectable(self) -> bool {
        matches!(
            self,
            FaultKind::SensorOutOfRange | FaultKind::ConversionFailed | FaultKind::DacWriteFailed
        )
    }
}

/// The campaign's settings.
#[derive(Debug, Clone)]
pub struct Campaign {
    pub seeds: u64,
    /// Samples per case (100 kHz loop).
    pub samples: u64,
    /// Controllers by registry name (empty: all).
    pub controllers: Vec<String>,
    pub faults: Vec<FaultKind>,
}

impl Default for Campaign {
    fn default() -> Self {
        Self {
            seeds: 100,
            samples: 3000,
            controllers: Vec::new(),
            faults: FaultKind::ALL.to_vec(),
        }
    }
}

/// Result of one case.
#[derive(Debug, Clone, Copy, Default)]
pub struct CaseResult {
    pub unsafe_outputs: u64,
    /// For detectable faults: samples from the fault to the safe command.
    pub samples_to_safe: Option<u64>,
    /// Detectable fault that never led to the safe state.
    pub missed: bool,
    pub recorder_lost: u64,
}

/// Totals per fault.
#[derive(Debug, Clone, Serialize)]
pub struct ByFault {
    pub fault: String,
    pub cases: u64,
    pub unsafe_outputs: u64,
    pub detectable: bool,
    /// Detectable faults that did not reach the safe state.
    pub missed_detections: u64,
    pub max_samples_to_safe: u64,
    pub recorder_samples_lost: u64,
}

/// The campaign's report (the JSON of `piezo faults --json`).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub cases: u64,
    pub unsafe_outputs: u64,
    pub max_samples_to_safe: u64,
    pub recorder_samples_lost: u64,
    pub controllers: Vec<String>,
    pub by_fault: Vec<ByFault>,
}

/// The stage every case starts from: the default 1-axis stage tracking a 50 Hz sine over
/// 80 % of the stroke.
pub fn base_scenario(samples: u64) -> Scenario {
    let mut sc = Scenario {
        name: "faults".into(),
        ..Scenario::default()
    };
    sc.reference.freq_hz = 50.0;
    sc.run.duration_s = samples as f64 / sc.run.loop_hz;
    sc
}

/// One fault as it is injected into a case.
struct Injector {
    kind: FaultKind,
    start: u64,
    len: u64,
    rng: Rng,
    /// Size: noise amplitude (codes), out-of-range offset, ...
    size: f64,
    stuck: Option<i32>,
    last: [i32; 1],
    /// Sensor window (codes).
    window: (i32, i32),
}

impl Injector {
    fn active(&self, k: u64) -> bool {
        k >= self.start && k < self.start + self.len
    }
}

impl Inject<1> for Injector {
    fn adc(&mut self, k: u64, codes: &mut [i32; 1]) {
        let on = self.active(k);
        let fresh = codes[0];
        match self.kind {
            FaultKind::SensorStuck if on => {
                codes[0] = *self.stuck.get_or_insert(fresh);
            }
            FaultKind::SensorOutOfRange if on => {
                let (lo, hi) = self.window;
                codes[0] = match self.rng.next_u64() % 4 {
                    0 => hi.saturating_add(1 + self.size as i32),
                    1 => lo.saturating_sub(1 + self.size as i32),
                    2 => i32::MAX,
                    _ => i32::MIN,
                };
            }
            FaultKind::NoiseBurst if on => {
                let c = codes[0] as f64 + self.size * self.rng.gauss();
                codes[0] = c.clamp(i32::MIN as f64, i32::MAX as f64) as i32;
            }
            FaultKind::DuplicatedSamples if on => codes[0] = self.last[0],
            _ => {}
        }
        self.last = [fresh];
    }

    fn skip_step(&mut self, k: u64) -> bool {
        match self.kind {
            FaultKind::DroppedSamples => self.active(k),
            FaultKind::Overrun => self.active(k) && (k - self.start) % 2 == 1,
            _ => false,
        }
    }

    fn dac_write_fails(&mut self, k: u64, _axis: usize) -> bool {
        self.kind == FaultKind::DacWriteFailed && self.active(k)
    }
}

/// A DAC code outside `range`, or a step from `prev` larger than `max_step` codes.
pub fn unsafe_output(prev: i32, code: i32, range: (i32, i32), max_step: i32) -> bool {
    code < range.0 || code > range.1 || (code as i64 - prev as i64).abs() > max_step as i64
}

/// Runs one case: `kind` with `seed` on the controller `entry`.
pub fn run_case(
    nominal: &Scenario,
    linear: &piezo_core::feedforward::LinearFf<f64>,
    entry: &Entry,
    kind: FaultKind,
    seed: u64,
) -> Result<CaseResult> {
    let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ kind as u64);
    let n = (nominal.run.duration_s * nominal.run.loop_hz).round() as u64;
    let start = n / 10 + rng.next_u64() % (n / 2);
    let len = 1 + rng.next_u64() % (n / 5);

    // The stage the controller does not know about.
    let mut stage_sc = nominal.clone();
    stage_sc.run.seed = seed;
    match kind {
        FaultKind::AmplifierSaturation => {
            let a = &mut stage_sc.stage.amplifier;
            let span = a.rail_max_volts - a.rail_min_volts;
            a.rail_max_volts = a.rail_min_volts + span * (0.5 + 0.3 * rng.uniform());
        }
        FaultKind::ParameterDrift => {
            let h = &mut stage_sc.stage.hysteresis;
            let mut f = || 1.0 + 0.4 * (rng.uniform() - 0.5);
            h.d *= f();
            h.alpha *= f();
            h.beta *= f();
            h.gamma *= f();
        }
        FaultKind::StepLoad => {
            let stroke_um = 2.0 * nominal.reference.amplitude_um;
            let f = &mut stage_sc.stage.force;
            f.enabled = true;
            f.freq_hz = 0.0;
            let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            f.newtons = sign * 0.37 * stroke_um * f.stiffness_n_per_um;
            f.at_s = start as f64 / nominal.run.loop_hz;
        }
        _ => {}
    }
    let info = StageInfo {
        scenario: nominal,
        linear: *linear,
    };
    let controller = (entry.one_axis)(&info)?;
    let mut bench = Bench::<1>::new(&stage_sc, controller, linear)?;
    let out = bench
        .pipeline
        .output(0)
        .ok_or_else(|| anyhow!("pipeline has no axis 0"))?;
    let (code_lo, code_hi) = out.code_range();
    let max_step = out.max_step();
    let safe_volts = bench.pipeline.config().axes[0].safe_volts;
    let s = bench.pipeline.config().axes[0].sensor;
    let noise_codes = (stage_sc.converters.adc_noise_lsb.max(1.0)
        + stage_sc.stage.noise.sigma_um / (s.um_per_code.abs() as f64))
        .max(1.0);
    let mut inj = Injector {
        kind,
        start,
        len,
        size: match kind {
            FaultKind::NoiseBurst => 100.0 * noise_codes,
            _ => (rng.next_u64() % 100_000) as f64,
        },
        rng,
        stuck: None,
        last: [0],
        window: (s.code_min, s.code_max),
    };

    // Recorder: armed before the fault, y / u / DAC code of every control period.
    let mut rec: ArrayRecorder<R, 3, 512> = ArrayRecorder::new();
    rec.select(&[Signal::YUm, Signal::UVolts, Signal::DacCode])
        .map_err(|e| anyhow!(e.message()))?;
    rec.set_trigger(Trigger::Now, 0)
        .map_err(|e| anyhow!(e.message()))?;
    let arm_at = start.saturating_sub(128);
    let mut shadow: Vec<[R; 3]> = Vec::with_capacity(512);

    let mut res = CaseResult::default();
    let mut prev_code = bench.dac_codes()[0];
    let mut fault_seen_at: Option<u64> = None;
    for k in 0..n {
        if kind == FaultKind::ConversionFailed && k == start {
            bench.adcs[0].chip.fail_transactions(len as u32);
        }
        if k == arm_at {
            rec.arm();
        }
        let before = bench.pipeline.state().counters.samples;
        bench.step_with(&mut inj);
        let st = bench.pipeline.state();
        let ran = st.counters.samples != before;

        // Safety at the converter.
        let code = bench.dac_codes()[0];
        if unsafe_output(prev_code, code, (code_lo, code_hi), max_step) {
            res.unsafe_outputs += 1;
        }
        prev_code = code;

        // Detection and time to the safe command.
        if kind.detectable() && k >= start && fault_seen_at.is_none() && ran {
            fault_seen_at = Some(k);
        }
        if let (Some(k0), None) = (fault_seen_at, res.samples_to_safe) {
            if st.fault.is_some() && st.trace.u_cmd[0] == safe_volts {
                res.samples_to_safe = Some(k - k0);
            }
        }

        // Recorder: what the control task would push this period.
        if ran {
            let mut sig = [0.0 as R; Signal::COUNT];
            sig[Signal::YUm.index()] = st.trace.y_um[0];
            sig[Signal::UVolts.index()] = st.u_applied[0];
            sig[Signal::DacCode.index()] = st.code[0] as R;
            let busy = matches!(
                rec.state(),
                piezo_core::recorder::State::Armed | piezo_core::recorder::State::Triggered
            );
            if busy {
                shadow.push([
                    sig[Signal::YUm.index()],
                    sig[Signal::UVolts.index()],
                    sig[Signal::DacCode.index()],
                ]);
            }
            rec.push(&sig);
        }
    }
    if kind.detectable() && fault_seen_at.is_some() && res.samples_to_safe.is_none() {
        res.missed = true;
    }
    // Every frame pushed into the finished capture must come back unchanged.
    let expected = shadow.len().min(512);
    let mut matched = 0;
    for (i, want) in shadow.iter().take(expected).enumerate() {
        if let Some(got) = rec.frame(i) {
            if got
                .iter()
                .zip(want)
                .all(|(a, b)| a.to_bits() == b.to_bits())
            {
                matched += 1;
            }
        }
    }
    res.recorder_lost = (expected - matched) as u64;
    Ok(res)
}

/// Runs the campaign (cases in parallel); `progress` is called after each fault kind.
pub fn run(c: &Campaign, progress: &(dyn Fn(&str) + Sync)) -> Result<Report> {
    let nominal = base_scenario(c.samples);
    let linear = calibrate(&nominal)?;
    let entries: Vec<Entry> = registry()
        .into_iter()
        .filter(|e| {
            c.controllers.is_empty()
                || c.controllers
                    .iter()
                    .any(|n| piezo_core::registry::canonical(n) == e.name)
        })
        .collect();
    if entries.is_empty() {
        return Err(anyhow!(
            "no controller matches {:?}; see `piezo sim --list`",
            c.controllers
        ));
    }
    let mut by_fault = Vec::new();
    for &kind in &c.faults {
        let jobs: Vec<(usize, u64)> = (0..entries.len())
            .flat_map(|e| (0..c.seeds).map(move |s| (e, s)))
            .collect();
        let results: Vec<CaseResult> = jobs
            .par_iter()
            .map(|&(e, s)| run_case(&nominal, &linear, &entries[e], kind, s))
            .collect::<Result<_>>()?;
        let mut b = ByFault {
            fault: kind.name().into(),
            cases: results.len() as u64,
            unsafe_outputs: 0,
            detectable: kind.detectable(),
            missed_detections: 0,
            max_samples_to_safe: 0,
            recorder_samples_lost: 0,
        };
        for r in &results {
            b.unsafe_outputs += r.unsafe_outputs;
            b.missed_detections += r.missed as u64;
            b.max_samples_to_safe = b.max_samples_to_safe.max(r.samples_to_safe.unwrap_or(0));
            b.recorder_samples_lost += r.recorder_lost;
        }
        progress(&format!(
            "{}: {} cases, {} unsafe",
            b.fault, b.cases, b.unsafe_outputs
        ));
        by_fault.push(b);
    }
    Ok(Report {
        cases: by_fault.iter().map(|b| b.cases).sum(),
        unsafe_outputs: by_fault.iter().map(|b| b.unsafe_outputs).sum(),
        max_samples_to_safe: by_fault
            .iter()
            .map(|b| b.max_samples_to_safe)
            .max()
            .unwrap_or(0),
        recorder_samples_lost: by_fault.iter().map(|b| b.recorder_samples_lost).sum(),
        controllers: entries.iter().map(|e| e.name.to_string()).collect(),
        by_fault,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(kind: FaultKind, seeds: u64) -> Vec<CaseResult> {
        let nominal = base_scenario(1500);
        let linear = calibrate(&nominal).unwrap();
        let e = registry().into_iter().next().unwrap();
        (0..seeds)
            .map(|s| run_case(&nominal, &linear, &e, kind, s).unwrap())
            .collect()
    }

    #[test]
    fn unsafe_output_flags_range_and_slew() {
        assert!(!unsafe_output(10, 20, (0, 100), 10));
        assert!(unsafe_output(10, 21, (0, 100), 10));
        assert!(unsafe_output(95, 101, (0, 100), 10));
        assert!(unsafe_output(0, -1, (0, 100), 10));
        // No overflow at the extremes.
        assert!(unsafe_output(
            i32::MAX,
            i32::MIN,
            (i32::MIN, i32::MAX),
            i32::MAX
        ));
    }

    /// A DAC failure the pipeline is not told about (the wrong held code) must show up as
    /// an unsafe step when the DAC comes back: the checker sees the converter, not the
    /// pipeline's belief.
    #[test]
    fn unreported_dac_failure_is_caught_by_the_checker() {
        let nominal = base_scenario(1500);
        let linear = calibrate(&nominal).unwrap();
        let e = registry().into_iter().next().unwrap();
        let c = (e.one_axis)(&StageInfo {
            scenario: &nominal,
            linear,
        })
        .unwrap();
        let mut bench = Bench::<1>::new(&nominal, c, &linear).unwrap();
        let o = *bench.pipeline.output(0).unwrap();
        let (lo, hi) = o.code_range();
        for _ in 0..200 {
            bench.step();
        }
        let before = bench.dac_codes()[0];
        // Lie to the pipeline: it believes the DAC holds the top code.
        bench.pipeline.dac_write_failed(0, hi);
        bench.pipeline.clear_fault();
        bench.step();
        let after = bench.dac_codes()[0];
        assert!(unsafe_output(before, after, (lo, hi), o.max_step()));
    }

    #[test]
    fn out_of_range_sensor_reaches_safe_state_at_once() {
        for r in one(FaultKind::SensorOutOfRange, 3) {
            assert_eq!(r.unsafe_outputs, 0);
            assert_eq!(r.samples_to_safe, Some(0));
            assert!(!r.missed);
            assert_eq!(r.recorder_lost, 0);
        }
    }

    #[test]
    fn failed_dac_write_is_detected_and_slew_holds() {
        for r in one(FaultKind::DacWriteFailed, 3) {
            assert_eq!(r.unsafe_outputs, 0);
            assert!(r.samples_to_safe.is_some());
        }
    }
}
