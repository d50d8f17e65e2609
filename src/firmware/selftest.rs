//! What `selftest` finds, as reply text: the DAC read-back of both boards and the on-chip
//! DAC's scale as its pin sees it (H743, one axis).
//!
//! The scale (issue 27 item 3): the H743's DAC runs with its output buffer off (code 0 is
//! 0 V), so its pin has a source impedance of about 15 kOhm (DS12110). A load on the pin, the
//! classic 10 kOhm pull-down wired straight to it, divides the output (to 0.4 of what the
//! firmware commands) and nothing else in the loop notices: feedback hides it, feedforward
//! and every open-loop mode are off by that factor. ADC2 converts the pin itself (PA4 is
//! ADC12_INP18); the DAC and the ADC share VREF+, so the pin's code over the DAC's, each
//! over its full scale, is the scale with no voltage in between.

use super::target::REPLY_LEN;
use crate::command::Reply;

/// `selftest`'s DAC read-back: ` <read>/<wrote> ok` (or ` BAD` when they differ), or
/// `no-period BAD` when no control period ran to do the write and read-back.
pub fn push_dac_readback<const N: usize>(r: &mut Reply<N>, read_wrote: Option<(i32, i32)>) {
    match read_wrote {
        Some((read, wrote)) => {
            r.push_i32(read);
            r.push_str("/");
            r.push_i32(wrote);
            r.push_str(if read == wrote { " ok" } else { " BAD" });
        }
        None => r.push_str("no-period BAD"),
    }
}

/// The DAC's code at the conversion must be at least this share of its full scale
/// (thousandths): below it the ADC's offset and noise would dominate the ratio.
pub const SCALE_MIN_CODE_MILLI: u32 = 100;
/// The scale passes within this many thousandths of 1: well above the converters' own gain
/// and offset errors (not measured here), well below the tens of percent of a divider.
pub const SCALE_TOLERANCE_MILLI: u32 = 30;

/// What the pin's conversion says about the DAC's scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DacScale {
    /// Pin over DAC, each over its full scale, in thousandths (1000: the pin has what the
    /// DAC puts out).
    Milli(u32),
    /// The DAC's code is below [`SCALE_MIN_CODE_MILLI`] of its full scale.
    LowOutput,
    /// The DAC's code changed during the conversion (the loop moved it).
    Moving,
    /// The ADC gave no result in time (busy or not converting).
    NoConversion,
}

/// The scale from the DAC's output code before and after the pin's conversion (`dac_bits`
/// wide) and the conversion's result (`adc_bits` wide), when there was one.
pub fn dac_scale(
    dac_before: u32,
    dac_after: u32,
    pin: Option<u32>,
    dac_bits: u32,
    adc_bits: u32,
) -> DacScale {
    let (dac_full, adc_full) = (full_scale(dac_bits), full_scale(adc_bits));
    let Some(pin) = pin else {
        return DacScale::NoConversion;
    };
    // A move of more than one part in a thousand of full scale: not a steady output.
    if dac_before.abs_diff(dac_after) as u64 * 1000 > dac_full {
        return DacScale::Moving;
    }
    let dac = dac_before.min(dac_after) as u64;
    if dac == 0 || adc_full == 0 || dac * 1000 < dac_full * SCALE_MIN_CODE_MILLI as u64 {
        return DacScale::LowOutput;
    }
    // In u128 every product of 32-bit codes fits; the divisor is not 0 here.
    let num = pin.min(adc_full as u32) as u128 * dac_full as u128 * 1000;
    let den = dac as u128 * adc_full as u128;
    // `checked_div`: no division-by-zero panic path in the command task (den > 0 anyway).
    let milli = num.saturating_add(den / 2).checked_div(den).unwrap_or(0);
    DacScale::Milli(milli.min(u32::MAX as u128) as u32)
}

fn full_scale(bits: u32) -> u64 {
    (1u64 << bits.min(32)) - 1
}

/// ` scale <ratio> ok|LOW|HIGH` or ` scale n/a (<why>)`.
pub fn push_dac_scale(r: &mut Reply<REPLY_LEN>, s: DacScale) {
    r.push_str(" scale ");
    match s {
        DacScale::Milli(m) => {
            r.push_fixed(m, 3);
            r.push_str(if m.abs_diff(1000) <= SCALE_TOLERANCE_MILLI {
                " ok"
            } else if m < 1000 {
                " LOW (a load on the unbuffered DAC pin? buffer first, pull-down behind it)"
            } else {
                " HIGH"
            });
        }
        DacScale::LowOutput => r.push_str("n/a (DAC below 10 % of its range: hold mid-stroke)"),
        DacScale::Moving => r.push_str("n/a (the output moved: hold a constant output)"),
        DacScale::NoConversion => r.push_str("n/a (no conversion of the pin)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The pin's 16-bit code of an unbuffered 12-bit DAC (about 15 kOhm source) at `code`,
    /// loaded by `r_load` ohms to ground (`None`: no load, or a buffer).
    fn pin(code: u32, r_load: Option<f64>) -> u32 {
        let share = r_load.map_or(1.0, |r| r / (r + 15e3));
        (code as f64 / 4095.0 * share * 65535.0).round() as u32
    }

    fn text(s: DacScale) -> std::string::String {
        let mut r = Reply::<REPLY_LEN>::new();
        push_dac_scale(&mut r, s);
        std::string::String::from_utf8_lossy(r.as_bytes()).into_owned()
    }

    #[test]
    fn a_pull_down_on_the_unbuffered_pin_reads_low_and_a_buffered_output_passes() {
        let code = 2048;
        let buffered = dac_scale(code, code, Some(pin(code, None)), 12, 16);
        assert_eq!(buffered, DacScale::Milli(1000));
        assert_eq!(text(buffered), " scale 1.000 ok");
        // 10 kOhm straight on the pin: 10 / 25 = 0.4 of the output.
        let pulled = dac_scale(code, code, Some(pin(code, Some(10e3))), 12, 16);
        assert_eq!(pulled, DacScale::Milli(400));
        assert!(
            text(pulled).starts_with(" scale 0.400 LOW"),
            "{}",
            text(pulled)
        );
        // An amplifier input of 10 MOhm on the pin: inside the tolerance.
        let amp = dac_scale(code, code, Some(pin(code, Some(10e6))), 12, 16);
        assert!(text(amp).ends_with(" ok"), "{}", text(amp));
    }

    #[test]
    fn no_verdict_where_the_measurement_cannot_give_one() {
        assert_eq!(dac_scale(0, 0, Some(0), 12, 16), DacScale::LowOutput);
        assert_eq!(dac_scale(409, 409, Some(6550), 12, 16), DacScale::LowOutput);
        assert_eq!(dac_scale(2000, 2100, Some(32000), 12, 16), DacScale::Moving);
        assert_eq!(dac_scale(2000, 2000, None, 12, 16), DacScale::NoConversion);
        assert!(text(DacScale::LowOutput).contains("n/a"));
    }

    proptest! {
        #[test]
        fn any_codes_give_an_answer(
            a in any::<u32>(), b in any::<u32>(), p in proptest::option::of(any::<u32>()),
            db in 0u32..40, ab in 0u32..40,
        ) {
            let s = dac_scale(a, b, p, db, ab);
            let t = text(s);
            prop_assert!(t.starts_with(" scale "));
        }
    }
}
