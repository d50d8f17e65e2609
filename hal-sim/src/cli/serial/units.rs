//! Quantities with units on the command line (`5um`, `300nm`, `2kHz`, `20V/ms`); bare
//! numbers are in um, Hz, V and V/s.

/// A number with an optional unit; bare numbers are in `base`.
fn quantity(s: &str, what: &str, units: &[(&str, f64)]) -> Result<f64, String> {
    let t = s.trim();
    let split = t
        .char_indices()
        .find(|&(i, c)| {
            !(c.is_ascii_digit()
                || c == '.'
                || ((c == '-' || c == '+')
                    && (i == 0 || t[..i].ends_with('e') || t[..i].ends_with('E')))
                || ((c == 'e' || c == 'E')
                    && t[i + 1..]
                        .starts_with(|d: char| d.is_ascii_digit() || d == '-' || d == '+')))
        })
        .map(|(i, _)| i)
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let unit = unit.trim();
    let v: f64 = num
        .parse()
        .map_err(|_| format!("`{s}`: not a {what} (a number, optionally with a unit)"))?;
    let names = || units.iter().map(|(u, _)| *u).collect::<Vec<_>>().join(", ");
    let factor = if unit.is_empty() {
        1.0
    } else {
        units
            .iter()
            .find(|(u, _)| *u == unit)
            .map(|(_, f)| *f)
            .ok_or_else(|| format!("`{s}`: unknown unit `{unit}` for a {what}; use {}", names()))?
    };
    let v = v * factor;
    if !v.is_finite() || v.abs() > f32::MAX as f64 {
        return Err(format!("`{s}`: not a finite {what}"));
    }
    Ok(v)
}

/// Position in um (`12.5`, `12.5um`, `300nm`, `0.1mm`).
pub fn parse_um(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "position",
        &[("um", 1.0), ("µm", 1.0), ("nm", 1e-3), ("mm", 1e3)],
    )
}

/// Frequency in Hz (`100`, `100Hz`, `2kHz`, `25MHz`, `500mHz`).
pub fn parse_hz(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "frequency",
        &[("Hz", 1.0), ("kHz", 1e3), ("MHz", 1e6), ("mHz", 1e-3)],
    )
}

/// Duration in s (`10`, `10s`, `500ms`, `2min`).
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "duration",
        &[("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("min", 60.0)],
    )
}

/// Voltage in V (`120`, `120V`, `500mV`).
pub fn parse_volts(s: &str) -> Result<f64, String> {
    quantity(s, "voltage", &[("V", 1.0), ("mV", 1e-3), ("kV", 1e3)])
}

/// Slew rate in V/s (`20000`, `20V/ms`, `20kV/s`, `0.02V/us`).
pub fn parse_volts_per_s(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "slew rate",
        &[
            ("V/s", 1.0),
            ("kV/s", 1e3),
            ("V/ms", 1e3),
            ("V/us", 1e6),
            ("V/µs", 1e6),
        ],
    )
}

/// f64 quantity as the protocol's f32 (already checked finite and in range).
pub fn f32_of(v: f64) -> f32 {
    v as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn units_scale_and_unknown_units_fail() {
        assert_eq!(parse_um("5"), Ok(5.0));
        assert_eq!(parse_um("5um"), Ok(5.0));
        assert_eq!(parse_um("-2.5 um"), Ok(-2.5));
        assert!((parse_um("300nm").unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(parse_um("0.1mm"), Ok(100.0));
        assert_eq!(parse_um("1e1um"), Ok(10.0));
        assert_eq!(parse_hz("2kHz"), Ok(2000.0));
        assert_eq!(parse_volts_per_s("20V/ms"), Ok(20_000.0));
        assert_eq!(parse_volts("120V"), Ok(120.0));
        let e = parse_um("5 furlong").unwrap_err();
        assert!(e.contains("unknown unit `furlong`"), "{e}");
        assert!(parse_hz("fast").is_err());
        assert!(parse_hz("1e60Hz").is_err());
        assert!(parse_volts("nan").is_err());
    }

    proptest! {
        #[test]
        fn garbage_quantities_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            if let Ok(s) = std::str::from_utf8(&bytes) {
                let _ = parse_um(s);
            }
        }
    }
}
