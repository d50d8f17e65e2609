//! The firmware's settings, one table (issue 14 item 1): name, unit, what it sets and who may
//! change it. `get`/`set`/`help`, the stored record, the protocol's parameter table
//! (`src/command.rs`, checked against this one by `tests/settings_table.rs`) and the host's
//! `piezo serial params` take their names and units from here. The values live in the
//! output limits, the converter scalings and [`super::Params`] (defaults there); `set`
//! checks a value through the core's constructors.

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
}

/// One setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setting {
    pub name: &'static str,
    pub unit: &'static str,
    pub about: &'static str,
    pub access: Access,
}

const fn s(name: &'static str, unit: &'static str, about: &'static str, access: Access) -> Setting {
    Setting {
        name,
        unit,
        about,
        access,
    }
}

/// Every setting, in the order `help` lists them.
pub const SETTINGS: [Setting; 20] = [
    s("u_min", "V", "lowest output voltage", Access::Limit),
    s(
        "u_max",
        "V",
        "highest output voltage (at most 150)",
        Access::Limit,
    ),
    s("slew", "V/s", "output slew-rate limit", Access::Limit),
    s(
        "um_per_code",
        "um",
        "position per ADC code",
        Access::ReadOnly,
    ),
    s(
        "volts_per_code",
        "V",
        "output voltage per DAC code",
        Access::ReadOnly,
    ),
    s("sample_hz", "Hz", "control rate", Access::ReadOnly),
    s(
        "cbw_d",
        "um/V",
        "CBW piezo gain d (000 eq. 1)",
        Access::Model,
    ),
    s("cbw_alpha", "um/V", "CBW alpha (000 eq. 2)", Access::Model),
    s("cbw_beta", "1/V", "CBW beta", Access::Model),
    s("cbw_gamma", "1/V", "CBW gamma", Access::Model),
    s(
        "gbw_b",
        "1/V",
        "GBW asymmetry B of fts-gbw and nmpc-gbw (000 eq. 3)",
        Access::Model,
    ),
    s("um_per_volt", "um/V", "open-loop scaling", Access::Model),
    s("offset_um", "um", "open-loop offset", Access::Model),
    s("hgo_eps", "s", "HGO epsilon (000 eq. 6)", Access::Model),
    s(
        "lambda1",
        "1/s",
        "robust law gain (000 eq. 7)",
        Access::Model,
    ),
    s(
        "lambda2",
        "1/s",
        "robust law gain (000 eq. 7)",
        Access::Model,
    ),
    s("pid_kp", "V/um", "PID proportional gain", Access::Model),
    s("pid_ki", "V/(um s)", "PID integral gain", Access::Model),
    s(
        "notch_hz",
        "Hz",
        "notch on the measured position (0 = off, else 10 Hz to 0.45 of the sample rate)",
        Access::Model,
    ),
    s(
        "notch_q",
        "1",
        "notch quality factor (0.5 to 50)",
        Access::Model,
    ),
];

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
pub const PARAMS: [&str; 20] = names(None);
/// The settings only `get` reads.
pub const READ_ONLY: [&str; 3] = names(Some(Access::ReadOnly));

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
        // Every model setting is a slot of Params.
        let mut p = super::super::Params::default();
        for s in SETTINGS.iter().filter(|s| s.access == Access::Model) {
            assert!(p.slot(s.name).is_some(), "{}", s.name);
        }
    }
}
