//! `piezo fit`'s command line (its own file so that the fitting modules can take it without
//! importing the command that dispatches to them).
use crate::ident::optim::Optimizer;
use crate::record::{Layout, Record};
use std::path::{Path, PathBuf};

/// Where the records keep time, inputs and outputs, and the units of columns that name
/// none: one definition for `piezo fit`, `diagnose` and `predict` (the convention is
/// `crate::record`'s).
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct Columns {
    /// Time column, by its header name (default: `t` or `t_<unit>`, e.g. `t_s`, `t_ms`).
    #[arg(long, value_name = "NAME")]
    pub t_col: Option<String>,
    /// Input columns by header name, in channel order: repeat or a comma list (default:
    /// `u` or `u1..uk`, with or without a unit, e.g. `u_V`, `u_volts`, `u_mV`).
    #[arg(long, value_name = "NAME", value_delimiter = ',')]
    pub u_col: Vec<String>,
    /// Output columns by header name, in channel order: repeat or a comma list (default:
    /// `y` or `y1..yn`, with or without a unit, e.g. `y_um`, `y_nm`, `y_m`).
    #[arg(long, value_name = "NAME", value_delimiter = ',')]
    pub y_col: Vec<String>,
    /// Unit of input columns whose header names none (V or mV); read values are in V.
    #[arg(long, default_value = "V")]
    pub input_unit: String,
    /// Unit of output columns whose header names none (um, nm, mm or m); read values are
    /// in um.
    #[arg(long, default_value = "um")]
    pub output_unit: String,
}

impl Default for Columns {
    fn default() -> Self {
        let l = Layout::default();
        Self {
            t_col: None,
            u_col: Vec::new(),
            y_col: Vec::new(),
            input_unit: l.u_unit,
            output_unit: l.y_unit,
        }
    }
}

impl Columns {
    /// The record layout these options select; `outputs_optional` for input records.
    pub fn layout(&self, outputs_optional: bool) -> Layout {
        Layout {
            t: self.t_col.clone(),
            u: self.u_col.clone(),
            y: self.y_col.clone(),
            u_unit: self.input_unit.clone(),
            y_unit: self.output_unit.clone(),
            outputs_optional,
        }
    }

    /// Reads a record (with outputs) through `crate::record`; a unit the header did not
    /// state is said on stderr unless `quiet`.
    pub fn read(&self, path: &Path, quiet: bool) -> anyhow::Result<Record> {
        self.read_layout(path, &self.layout(false), quiet)
    }

    /// [`Columns::read`] for a record that may hold inputs only (`y` then empty).
    pub fn read_inputs(&self, path: &Path, quiet: bool) -> anyhow::Result<Record> {
        self.read_layout(path, &self.layout(true), quiet)
    }

    fn read_layout(&self, path: &Path, layout: &Layout, quiet: bool) -> anyhow::Result<Record> {
        let r = Record::read_with(path, layout)?;
        if let (Some(note), false) = (&r.unit_note, quiet) {
            eprintln!("note: record {}: {note}", path.display());
        }
        Ok(r)
    }
}

/// The records a model is fitted and validated on, the same options for `piezo fit` and
/// `piezo diagnose`.
#[derive(clap::Args, Debug, Clone)]
pub struct Records {
    /// Training record (CSV: `t_s,u_V,y_um` or `t_s,u1_V..uk_V,y1_um..yn_um`; units
    /// optional; other columns with --t-col, --u-col, --y-col). Repeat for several:
    /// `diagnose` and the state-space models (`ss`, `hammerstein-ss`, `scheduled-ss`) fit
    /// one model on all of them.
    #[arg(long)]
    pub train: Vec<PathBuf>,
    /// Validation record, never used for fitting, ideally with another excitation. Repeat
    /// for several (`diagnose` measures its gains on all of them).
    #[arg(long, conflicts_with = "split")]
    pub valid: Vec<PathBuf>,
    /// Without --valid: split each training record at this fraction of its samples
    /// (0.1..0.9): the first part fits, the model runs on through the rest, which validates.
    #[arg(long)]
    pub split: Option<f64>,
    /// `diagnose`: fit only on this time window of every training record, `T0:T1` in
    /// seconds of its time column (e.g. the first cycles after a rest). The model starts at
    /// rest at the window's first sample: start it where the stage rests.
    #[arg(long, value_name = "T0:T1", conflicts_with = "split")]
    pub train_window: Option<Window>,
    /// `diagnose`: score only this time window of every validation record (of the training
    /// records without --valid); the model runs through the samples before it from the
    /// record's start.
    #[arg(long, value_name = "T0:T1", conflicts_with = "split")]
    pub valid_window: Option<Window>,
}

/// A time window `T0:T1` (seconds, `T0 < T1`; either side may be left empty: the record's
/// start or end).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub from_s: f64,
    pub to_s: f64,
}

impl std::str::FromStr for Window {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (a, b) = s
            .split_once(':')
            .ok_or_else(|| format!("window `{s}`: expected T0:T1 in seconds"))?;
        let side = |x: &str, open: f64| -> Result<f64, String> {
            if x.trim().is_empty() {
                return Ok(open);
            }
            x.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("window `{s}`: `{x}` is not a time in seconds"))
        };
        let w = Window {
            from_s: side(a, f64::NEG_INFINITY)?,
            to_s: side(b, f64::INFINITY)?,
        };
        if w.from_s < w.to_s {
            Ok(w)
        } else {
            Err(format!("window `{s}`: T0 must be below T1"))
        }
    }
}

impl Window {
    /// The samples `[k0, k1)` of time column `t` inside the window.
    pub fn samples(&self, t: &[f64]) -> (usize, usize) {
        let k0 = t.partition_point(|&x| x < self.from_s);
        let k1 = t.partition_point(|&x| x < self.to_s);
        (k0, k1.max(k0))
    }
}

impl Records {
    /// For the commands that do not take time windows: an error if one is given.
    pub fn no_windows(&self, what: &str) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.train_window.is_none() && self.valid_window.is_none(),
            "--train-window and --valid-window are `piezo diagnose` options; {what} takes --split or --valid"
        );
        Ok(())
    }

    /// The sample a record of `len` samples is split at (`--split`, else `default`; `None`
    /// with --valid or without either), the fraction checked.
    pub fn split_at(&self, len: usize, default: Option<f64>) -> anyhow::Result<Option<usize>> {
        if !self.valid.is_empty() {
            anyhow::ensure!(
                self.split.is_none(),
                "--split and --valid exclude each other"
            );
            return Ok(None);
        }
        let Some(f) = self.split.or(default) else {
            return Ok(None);
        };
        crate::ident::identify::split_sample(len, f).map(Some)
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model name (`piezo fit --list` shows them all), e.g. cbw, gbw, pi, structural-bw.
    #[arg(long, required_unless_present = "list")]
    pub model: Option<String>,
    /// Training and validation records.
    #[command(flatten)]
    pub records: Records,
    /// State-space models: order (number of states) or `auto` (chosen by validation on
    /// every fourth training record). Default: `auto`; `lfr`: 32.
    #[arg(long)]
    pub order: Option<String>,
    /// `hammerstein-ss`: hysteresis model of the core ahead of each input (a
    /// rate-independent `--list` name, e.g. cbw), or `none` (then the same as `ss`).
    #[arg(long, default_value = "cbw")]
    pub hysteresis: String,
    /// State-space models: iterations of the joint (hysteresis + linear) refinement.
    #[arg(long, default_value_t = 30)]
    pub joint_iterations: usize,
    /// `scheduled-ss`: time constant of the running input RMS that schedules the model (s).
    #[arg(long, default_value_t = 0.15)]
    pub schedule_tau_s: f64,
    /// `lfr`: basis functions of the nonlinearity in feedback, applied to every channel
    /// (comma list of `cubic` = z^3, `abs-square` = z |z|, `soft-cubic` = z - tanh z,
    /// `play:R` = play operator of half-width R, `rms:T` = z r / (1 + r) with r the
    /// channel's running mean square over T samples: a stiffness that follows the level;
    /// `mav:T` the same with the running mean of |z|).
    #[arg(long, value_delimiter = ',', default_value = crate::ident::ss::lfr::DEFAULT_BASIS)]
    pub lfr_basis: Vec<String>,
    /// `lfr`: the records the linear part is identified on: `all` (the BLA of every
    /// training record) or `lowest` (the lowest input level's: the small-signal model the
    /// feedback vanishes to; the feedback is then fitted on all). Default: lowest.
    #[arg(long)]
    pub lfr_linear: Option<String>,
    /// `lfr`: the nonlinearity's channels: `outputs` (one per output, `E`, `F` full),
    /// `outputs:K` (K per output at input gains spread by factors of 2, like the neurons of
    /// one hidden layer) or `modes` (one per lightly damped mode, each reading and feeding
    /// only its own mode).
    #[arg(long, default_value = "outputs:2")]
    pub lfr_channels: String,
    /// `lfr`: Levenberg-Marquardt iterations on the simulation error (it stops earlier when
    /// a step no longer lowers the cost); with static bases and ones with memory (`rms`,
    /// `mav`, `play`) together, each of the two stages' (the static bases first, then all
    /// from there).
    #[arg(long, default_value_t = 30)]
    pub lfr_iterations: usize,
    /// `lfr`: refuse every step of the fit whose model diverges from rest on the training
    /// inputs scaled by this factor (e.g. 1.5); default: no check.
    #[arg(long)]
    pub lfr_guard: Option<f64>,
    /// State-space models (`ss`, `hammerstein-ss`, `scheduled-ss`, `lfr`): the inputs reach
    /// the model this many samples late (an input delay, as `piezo diagnose --base` names
    /// it; periodic records are shifted within each period). Saved in fit.json.
    #[arg(long, default_value_t = 0, value_name = "SAMPLES")]
    pub input_delay: usize,
    /// Columns and units of the records.
    #[command(flatten)]
    pub columns: Columns,
    /// The validation record is one period of a periodic steady state: simulate this many
    /// periods of its input first and score the last (0: from rest).
    #[arg(long, default_value_t = 0)]
    pub valid_periodic: usize,
    /// Hammerstein: second-order linear sections after the hysteresis (004 eq. 8), 0..=2.
    #[arg(long, default_value_t = 0)]
    pub linear: usize,
    /// Hammerstein two-step (004 sec. 4.2): identify the linear part first on this record
    /// (PRBS or step response), then the hysteresis on --train with it fixed.
    #[arg(long)]
    pub linear_train: Option<PathBuf>,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write the simulated output of the validation record (or of the training record
    /// without --valid) as CSV: `y` simulated, measured output kept as `y_meas`.
    #[arg(long)]
    pub predict: Option<PathBuf>,
    /// Folder for plots (loops, time series, residuals), fit.json and index.html (the report
    /// with them).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Global search: differential evolution or particle swarm (002 sec. 3).
    #[arg(long, value_enum, default_value_t = Optimizer::De)]
    pub optimizer: Optimizer,
    /// Generations (DE) / iterations (PSO) of the global search (0: LM only).
    #[arg(long, default_value_t = 300)]
    pub generations: usize,
    /// DE population / PSO swarm size (0: 10 per parameter).
    #[arg(long, default_value_t = 0)]
    pub population: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Levenberg-Marquardt iterations of the local refinement.
    #[arg(long, default_value_t = 60)]
    pub lm_iterations: usize,
    /// Dynamic models: input upsampling for integration (the Bouc-Wen benchmark uses 20).
    #[arg(long, default_value_t = 20)]
    pub upsample: usize,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
    /// List the models and exit.
    #[arg(long)]
    pub list: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_parses_and_selects() {
        let w: Window = "1.5:2".parse().unwrap();
        assert_eq!((w.from_s, w.to_s), (1.5, 2.0));
        let open: Window = ":1".parse().unwrap();
        assert_eq!(open.from_s, f64::NEG_INFINITY);
        assert!("2:1".parse::<Window>().is_err());
        assert!("1".parse::<Window>().is_err());
        assert!("a:2".parse::<Window>().is_err());
        let t: Vec<f64> = (0..10).map(|k| k as f64 * 0.5).collect();
        assert_eq!(w.samples(&t), (3, 4));
        assert_eq!("3:".parse::<Window>().unwrap().samples(&t), (6, 10));
    }
}
