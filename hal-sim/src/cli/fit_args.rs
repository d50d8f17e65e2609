//! `piezo fit`'s command line (its own file so that the fitting modules can take it without
//! importing the command that dispatches to them).
use crate::ident::optim::Optimizer;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model name (`piezo fit --list` shows them all), e.g. cbw, gbw, pi, structural-bw.
    #[arg(long, required_unless_present = "list")]
    pub model: Option<String>,
    /// Training record (CSV: `t,u,y` or `t,u1..uk,y1..yn`). The state-space models
    /// (`ss`, `hammerstein-ss`, `scheduled-ss`) take several (repeat `--train`): one model
    /// for all.
    #[arg(long, required_unless_present = "list")]
    pub train: Vec<PathBuf>,
    /// State-space models: order (number of states) or `auto` (chosen by validation on
    /// every fourth training record).
    #[arg(long, default_value = "auto")]
    pub order: String,
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
    /// Unit of the input columns, written to fit.json.
    #[arg(long, default_value = "V")]
    pub input_unit: String,
    /// Unit of the output columns, written to fit.json.
    #[arg(long, default_value = "um")]
    pub output_unit: String,
    /// Validation record, simulated with the identified model (never used for fitting).
    #[arg(long)]
    pub valid: Option<PathBuf>,
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
    /// Folder for plots (loops, time series, residuals) and fit.json.
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
