//! The controller registry: a name -> pipeline configuration (feedforward + feedback +
//! mode) for a given stage.
//!
//! To add a controller: write one `fn my_law<const N: usize>(s: &StageInfo) ->
//! Result<Controller<N>>` (or one per axis count) and add one [`Entry`] to [`registry`].
//! The builder sees the nominal stage ([`StageInfo`]): the scenario's parameters and a
//! linear calibration measured on the stage.

mod feedforward;

use super::StageInfo;
use anyhow::Result;
use piezo_core::feedback::Feedback;
use piezo_core::feedforward::{Feedforward, LinearFf, MultiFeedforward};
use piezo_core::pipeline::Mode;

/// The number type of the simulated firmware (the firmware's own).
pub type R = f32;

/// What a registry entry builds: the pipeline's compensator, laws and mode.
#[derive(Debug, Clone)]
pub struct Controller<const N: usize> {
    pub feedforward: MultiFeedforward<R, N>,
    pub feedback: [Feedback<R>; N],
    pub mode: Mode,
}

/// Builder for a 1-axis stage.
pub type Build1 = fn(&StageInfo) -> Result<Controller<1>>;
/// Builder for a 2-axis stage (`None`: the controller has no 2-axis form).
pub type Build2 = fn(&StageInfo) -> Result<Controller<2>>;

/// One registered controller.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    /// Name on the command line and in the tables (`--controller NAME`).
    pub name: &'static str,
    /// One line for `piezo sim --list`.
    pub about: &'static str,
    pub one_axis: Build1,
    pub two_axis: Option<Build2>,
}

/// Every controller, in table order.
pub fn registry() -> Vec<Entry> {
    let mut v = vec![
        Entry {
            name: "open-loop",
            about: "linear scaling of the reference (calibrated gain and offset), no model, no feedback",
            one_axis: open_loop::<1>,
            two_axis: Some(open_loop::<2>),
        },
        // FEEDFORWARD and FEEDBACK: add entries here.
    ];
    v.extend(feedforward::entries());
    v
}

/// Looks a controller up by name.
pub fn find(name: &str) -> Option<Entry> {
    registry().into_iter().find(|e| e.name == name)
}

/// The linear feedforward of the calibrated stage, per axis.
pub fn linear_ff<const N: usize>(s: &StageInfo) -> [Feedforward<R>; N] {
    core::array::from_fn(|_| {
        Feedforward::Linear(LinearFf {
            um_per_volt: s.linear.um_per_volt as R,
            offset_um: s.linear.offset_um as R,
        })
    })
}

/// Open loop: the pipeline's linear scaling only.
pub fn open_loop<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    Ok(Controller {
        feedforward: MultiFeedforward::PerAxis(linear_ff(s)),
        feedback: core::array::from_fn(|_| Feedback::OpenLoop),
        mode: Mode::OpenLoop,
    })
}
