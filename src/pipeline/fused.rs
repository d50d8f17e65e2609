//! The fused step of the firmware's main mode: closed loop with the HGO + robust law
//! (exponential convergence, CBW observer with `n = 1`, no measurement filter) on the IMS-CBW
//! feedforward (solved loop), one axis.
//!
//! It does what [`Pipeline::step_generic`] does in that configuration, with the same
//! arithmetic in the same order (so the same results, bit for bit), in one straight
//! function: no dispatch over modes, compensators and laws per sample, and no guard that
//! cannot fire there. Which guards those are is decided once per configuration
//! ([`Pipeline::fusable`]): a valid ADC code scales into the input guard's bound, the
//! applied voltage (a code of the output range) and the IMS output (inside its voltage
//! range) too, so the law's input guard only has to hold the setpoint, and not even that
//! for a sine whose generator knows its setpoints lie inside the guard. The guards that
//! matter stay: an ADC code outside the sensor window, a fault, a law that has not primed
//! its observer yet or a non-finite command leave the sample (or its end) to the generic
//! path's safe-state handling, and the final range and slew limits are the same code.

use super::Pipeline;
use crate::feedback::guard::{inside_bound, INPUT_BOUND};
use crate::feedback::Feedback;
use crate::feedforward::{Feedforward, MultiFeedforward};
use crate::real::Real;

impl<T: Real, const N: usize> Pipeline<T, N> {
    /// The configuration runs the fused step (see the module documentation).
    pub(super) fn fusable(&self) -> bool {
        let (
            1,
            super::Mode::ClosedLoop,
            MultiFeedforward::PerAxis(ffs),
            Some(Feedback::Robust(law)),
            Some(axis),
            Some(out),
        ) = (
            N,
            self.state.mode,
            &self.feedforward,
            self.feedback.first(),
            self.config.axes.first(),
            self.output.first(),
        )
        else {
            return false;
        };
        let Some(Feedforward::ImsCbw(ims)) = ffs.first() else {
            return false;
        };
        let inside = |x: f64| inside_bound::<T>(x, INPUT_BOUND);
        let sensor = |code: i32| {
            axis.sensor.offset_um.to_f64() + axis.sensor.um_per_code.to_f64() * code as f64
        };
        let (lo, hi) = out.code_range();
        let volts = |code: i32| {
            out.dac.volts_at_zero.to_f64() + out.dac.volts_per_code.to_f64() * code as f64
        };
        let (ff_lo, ff_hi) = ims.volts_range();
        law.fusable()
            && ims.is_plain_cbw_n1()
            && inside(sensor(axis.sensor.code_min))
            && inside(sensor(axis.sensor.code_max))
            && inside(volts(lo))
            && inside(volts(hi))
            && inside(ff_lo.to_f64())
            && inside(ff_hi.to_f64())
    }

    /// One sample on the fused path; `None` (nothing changed) when it does not apply to
    /// this sample: the generic step runs it instead.
    #[inline(always)]
    pub(super) fn step_fused(&mut self, adc: [i32; N]) -> Option<[i32; N]> {
        let Self {
            config,
            output,
            reference,
            feedforward,
            feedback,
            state: st,
            ..
        } = self;
        let (
            Some(&adc),
            Some(axis),
            Some(out),
            Some(gen),
            MultiFeedforward::PerAxis(ffs),
            Some(Feedback::Robust(law)),
        ) = (
            adc.first(),
            config.axes.first(),
            output.first(),
            reference.first_mut(),
            feedforward,
            feedback.first_mut(),
        )
        else {
            return None;
        };
        let Some(Feedforward::ImsCbw(ims)) = ffs.first_mut() else {
            return None;
        };
        // A code outside the window: the generic path. The law is primed: the fused path
        // is decided only for a primed law (`Pending::Prime`), and only a restart, a new law
        // or `feedback_mut` unprime it, each of which decides again.
        let y = axis.sensor.position_um(adc)?;
        debug_assert!(!law.is_fresh());
        let (Some(y_tr), Some(sp_tr), Some(u_ff_tr), Some(u_cmd_tr), Some(code), Some(u_applied)) = (
            st.trace.y_um.first_mut(),
            st.trace.setpoint.first_mut(),
            st.trace.u_ff.first_mut(),
            st.trace.u_cmd.first_mut(),
            st.code.first_mut(),
            st.u_applied.first_mut(),
        ) else {
            return None;
        };
        st.counters.samples = st.counters.samples.saturating_add(1);
        *y_tr = y;
        let (sp, sp_within) = gen.next_setpoint_guarded();
        *sp_tr = sp;
        let target = law.fused_target(&sp, sp_within);
        let u_ff = ims.compensate_plain_cbw_n1(sp.y_um, sp_within);
        *u_ff_tr = u_ff;
        // The generic step's test for a non-finite command is left out: the robust law
        // returns a finite command or, if its own would not be, the applied voltage (finite
        // here), so the law's test is the one that matters. Whatever `u` is, the limits
        // below keep the code inside the range and the slew limit (NaN -> lowest code).
        let u = law.update_fused(target, y, u_ff, *u_applied);
        *u_cmd_tr = u;
        // The last code is always inside the output range (`new`, `limit` and
        // `dac_write_failed` put it there).
        let l = out.limit_from_code_in_range(u, *code);
        *code = l.code;
        *u_applied = out.dac.volts(l.code);
        if l.saturated {
            st.counters.saturated_samples = st.counters.saturated_samples.saturating_add(1);
        }
        Some(st.code)
    }
}
