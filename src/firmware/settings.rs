//! The firmware's settings, one table (issue 14 item 1): name, unit, what it sets and who may
//! change it. `get`/`set`/`help`, the stored record, the protocol's parameter table
//! (`src/command.rs`, checked against this one by `tests/settings_table.rs`) and the host's
//! `piezo serial params` take their names and units from here. The values live in the
//! output limits, the converter scalings and [`super::Params`] (defaults there); `set`
//! checks a value through the core's constructors.

use super::params::Params;
use super::target::{c, R};

/// Who changes a setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// An output limit: `set`, checked against the other limits.
    Limit,
    /// Fixed by the board's converters and rate: `get` only (`set` answers err 12).
    ReadOnly,
    /// The hysteresis model, the open-loop scaling or a gain ([`super::Params`]): `set`
    /// rebuilds the law and the compensator.
    Model,
    /// A sensor check (guard band, stuck-code limit): `set` changes it in place.
    Sensor,
}

/// A model setting's slot in [`Params`]: an enum and a `match`, not a function pointer,
/// so that the command handler makes no indirect call (the firmware safety check bounds its
/// stack and proves it free of panic paths).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    CbwD,
    CbwAlpha,
    CbwBeta,
    CbwGamma,
    GbwB,
    UmPerVolt,
    OffsetUm,
    HgoEpsS,
    Lambda1,
    Lambda2,
    PidKp,
    PidKi,
    NotchHz,
    NotchQ,
}

impl Params {
    /// The slot of `f`.
    pub fn field(&mut self, f: Field) -> &mut R {
        match f {
            Field::CbwD => &mut self.cbw_d,
            Field::CbwAlpha => &mut self.cbw_alpha,
            Field::CbwBeta => &mut self.cbw_beta,
            Field::CbwGamma => &mut self.cbw_gamma,
            Field::GbwB => &mut self.gbw_b,
            Field::UmPerVolt => &mut self.um_per_volt,
            Field::OffsetUm => &mut self.offset_um,
            Field::HgoEpsS => &mut self.hgo_eps_s,
            Field::Lambda1 => &mut self.lambda1,
            Field::Lambda2 => &mut self.lambda2,
            Field::PidKp => &mut self.pid_kp,
            Field::PidKi => &mut self.pid_ki,
            Field::NotchHz => &mut self.notch_hz,
            Field::NotchQ => &mut self.notch_q,
        }
    }
}

/// One setting: its name, unit and meaning, who changes it, its built-in value and the
/// range `set` accepts (a value outside it is `err 8` before any other check), and, for a
/// model setting, where it lives in [`Params`].
#[derive(Debug, Clone, Copy)]
pub struct Setting {
    pub name: &'static str,
    pub unit: &'static str,
    pub about: &'static str,
    pub access: Access,
    /// Built-in value (read-only settings: NaN, the board's converters decide).
    pub default: f64,
    /// Accepted range, inclusive; the laws' constructors and the other limits check more.
    pub min: f64,
    pub max: f64,
    /// The model setting's slot in [`Params`].
    pub field: Option<Field>,
}

impl Setting {
    /// Whether `v` is finite and inside the setting's range.
    pub fn accepts(&self, v: f64) -> bool {
        v.is_finite() && v >= self.min && v <= self.max
    }
}

/// A board setting (read-only): no default or range of its own.
const BOARD: [f64; 3] = [f64::NAN; 3];

const fn row(
    name: &'static str,
    unit: &'static str,
    about: &'static str,
    access: Access,
    [default, min, max]: [f64; 3],
    field: Option<Field>,
) -> Setting {
    Setting {
        name,
        unit,
        about,
        access,
        default,
        min,
        max,
        field,
    }
}

use Access::{Limit, Model, ReadOnly, Sensor};

/// Every setting, in the order `help` lists them: name, unit, meaning, access,
/// `[default, min, max]`, slot. Defaults: the QEMU board's simulated stage (CBW set 1 of the
/// 000 backup slide) and gains tuned on it; ranges: what a piezo stage behind a 150 V
/// amplifier can use, wide enough for any fitted model.
#[rustfmt::skip]
pub const SETTINGS: [Setting; 22] = [
    row("u_min", "V", "lowest output voltage", Limit, [0.0, 0.0, 150.0], None),
    row("u_max", "V", "highest output voltage (at most 150)", Limit, [150.0, 0.0, 150.0], None),
    row("slew", "V/s", "output slew-rate limit", Limit, [20_000.0, 1e-3, 1e9], None),
    // Up to 9 um: the window keeps the stage at rest (0 um, 10 um above the bottom rail).
    row("guard", "um", "sensor guard band: codes this close to either end of the ADC span are sensor faults", Sensor, [5.0, 0.0, 9.0], None),
    row("stuck", "samples", "identical consecutive ADC codes that are a sensor fault (0 = off)", Sensor, [100.0, 0.0, 10_000.0], None),
    row("um_per_code", "um", "position per ADC code", ReadOnly, BOARD, None),
    row("volts_per_code", "V", "output voltage per DAC code", ReadOnly, BOARD, None),
    row("sample_hz", "Hz", "control rate", ReadOnly, BOARD, None),
    row("cbw_d", "um/V", "CBW piezo gain d (000 eq. 1)", Model, [0.16, 1e-6, 1e3], Some(Field::CbwD)),
    row("cbw_alpha", "um/V", "CBW alpha (000 eq. 2)", Model, [0.07, -1e3, 1e3], Some(Field::CbwAlpha)),
    row("cbw_beta", "1/V", "CBW beta", Model, [0.02, -1e3, 1e3], Some(Field::CbwBeta)),
    row("cbw_gamma", "1/V", "CBW gamma", Model, [0.01, -1e3, 1e3], Some(Field::CbwGamma)),
    row("gbw_b", "1/V", "GBW asymmetry B of fts-gbw and nmpc-gbw (000 eq. 3)", Model, [0.0, -1e3, 1e3], Some(Field::GbwB)),
    row("um_per_volt", "um/V", "open-loop scaling", Model, [0.16, -1e3, 1e3], Some(Field::UmPerVolt)),
    row("offset_um", "um", "open-loop offset", Model, [0.0, -1e4, 1e4], Some(Field::OffsetUm)),
    row("hgo_eps", "s", "HGO epsilon (000 eq. 6)", Model, [2e-4, 1e-7, 1.0], Some(Field::HgoEpsS)),
    row("lambda1", "1/s", "robust law gain (000 eq. 7)", Model, [2_000.0, 0.0, 1e7], Some(Field::Lambda1)),
    row("lambda2", "1/s", "robust law gain (000 eq. 7)", Model, [2_000.0, 0.0, 1e7], Some(Field::Lambda2)),
    row("pid_kp", "V/um", "PID proportional gain", Model, [0.5, 0.0, 1e4], Some(Field::PidKp)),
    row("pid_ki", "V/(um s)", "PID integral gain", Model, [2_000.0, 0.0, 1e8], Some(Field::PidKi)),
    // The notch's own check ([`Params::notch`]) bounds it by the sample rate.
    row("notch_hz", "Hz", "notch on the measured position (0 = off, else 10 Hz to 0.45 of the sample rate)", Model, [0.0, 0.0, 1e6], Some(Field::NotchHz)),
    row("notch_q", "1", "notch quality factor (0.5 to 50)", Model, [2.0, 0.5, 50.0], Some(Field::NotchQ)),
];

/// The built-in value of the setting `name` (NaN for an unknown or read-only one).
pub fn default_of(name: &str) -> f64 {
    setting(name).map_or(f64::NAN, |s| s.default)
}

/// The setting of `name`.
pub fn setting(name: &str) -> Option<&'static Setting> {
    SETTINGS.iter().find(|s| s.name == name)
}

const fn names<const N: usize>(only: Option<Access>) -> [&'static str; N] {
    let mut out = [""; N];
    let (mut i, mut n) = (0, 0);
    while i < SETTINGS.len() {
        let keep = match only {
            None => true,
            Some(a) => SETTINGS[i].access as u8 == a as u8,
        };
        if keep && n < N {
            out[n] = SETTINGS[i].name;
            n += 1;
        }
        i += 1;
    }
    out
}

/// Names of `get`/`set` (and `help`'s list).
pub const PARAMS: [&str; 22] = names(None);
/// The settings only `get` reads.
pub const READ_ONLY: [&str; 3] = names(Some(Access::ReadOnly));

/// The parameters' built-in values and their slots by name come from [`SETTINGS`] (kept
/// here so that the table depends on [`Params`], not the other way round).
impl Default for Params {
    /// The defaults of the settings table ([`super::SETTINGS`]).
    fn default() -> Self {
        let zero = c(0.0);
        let mut p = Self {
            cbw_d: zero,
            cbw_alpha: zero,
            cbw_beta: zero,
            cbw_gamma: zero,
            gbw_b: zero,
            um_per_volt: zero,
            offset_um: zero,
            hgo_eps_s: zero,
            lambda1: zero,
            lambda2: zero,
            pid_kp: zero,
            pid_ki: zero,
            notch_hz: zero,
            notch_q: zero,
        };
        for s in SETTINGS.iter() {
            if let Some(f) = s.field {
                *p.field(f) = c(s.default);
            }
        }
        p
    }
}

impl Params {
    /// The slot of a model setting, by its `get`/`set` name ([`super::SETTINGS`]).
    pub(super) fn slot(&mut self, name: &str) -> Option<&mut R> {
        let f = SETTINGS.iter().find(|s| s.name == name)?.field?;
        Some(self.field(f))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_the_derived_lists_complete() {
        for (i, a) in SETTINGS.iter().enumerate() {
            assert!(SETTINGS[..i].iter().all(|b| b.name != a.name), "{}", a.name);
            assert!(!a.unit.is_empty() && !a.about.is_empty());
        }
        assert!(PARAMS.iter().all(|p| !p.is_empty()));
        let ro = SETTINGS
            .iter()
            .filter(|s| s.access == Access::ReadOnly)
            .count();
        assert_eq!(ro, READ_ONLY.len());
        assert!(READ_ONLY.iter().all(|p| !p.is_empty()));
        // Every model setting is a slot of Params, its default is the built-in value and
        // inside its range, and the slots are distinct.
        let mut p = Params::default();
        for (i, s) in SETTINGS.iter().enumerate() {
            let Some(f) = s.field else {
                assert!(s.access != Access::Model, "{}", s.name);
                continue;
            };
            assert!(s.accepts(s.default), "{} default outside its range", s.name);
            assert_eq!(*p.slot(s.name).unwrap(), c(s.default), "{}", s.name);
            *p.field(f) = c(1e-3 * i as f64 + 0.5);
        }
        for (i, s) in SETTINGS
            .iter()
            .enumerate()
            .filter(|(_, s)| s.field.is_some())
        {
            assert_eq!(
                *p.slot(s.name).unwrap(),
                c(1e-3 * i as f64 + 0.5),
                "{}",
                s.name
            );
        }
        for s in SETTINGS
            .iter()
            .filter(|s| matches!(s.access, Access::Limit | Access::Sensor))
        {
            assert!(s.accepts(s.default), "{}", s.name);
        }
    }
}
