//! The units of a record's time, input and output columns, and how a header names them.

use super::clip;

/// What a time, input or output column measures, with its accepted units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Time,
    Voltage,
    Length,
}

impl Quantity {
    /// Accepted unit names and the factor from each to the internal unit (s, V, um).
    pub fn units(self) -> &'static [(&'static str, f64)] {
        match self {
            Self::Time => &[("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("µs", 1e-6)],
            Self::Voltage => &[("V", 1.0), ("volts", 1.0), ("mV", 1e-3)],
            Self::Length => &[
                ("um", 1.0),
                ("µm", 1.0),
                ("μm", 1.0),
                ("nm", 1e-3),
                ("mm", 1e3),
                ("m", 1e6),
            ],
        }
    }

    /// The unit the tools compute in: s, V, um.
    pub fn internal(self) -> &'static str {
        self.units()[0].0
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Time => "time",
            Self::Voltage => "voltage",
            Self::Length => "length",
        }
    }

    /// Factor from `unit` to the internal unit; the error names the accepted units (and
    /// the quantity `unit` belongs to, when it is another one's).
    pub fn factor(self, unit: &str) -> Result<f64, String> {
        if let Some(&(_, f)) = self.units().iter().find(|(n, _)| *n == unit) {
            return Ok(f);
        }
        let accepted = self
            .units()
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", ");
        Err(match quantity_of(unit) {
            Some(q) => format!(
                "`{unit}` is a {} unit, not a {} unit ({accepted})",
                q.name(),
                self.name()
            ),
            None => format!(
                "unknown {} unit `{}` (accepted: {accepted})",
                self.name(),
                clip(unit)
            ),
        })
    }
}

/// The quantity whose accepted units include `unit`.
fn quantity_of(unit: &str) -> Option<Quantity> {
    [Quantity::Time, Quantity::Voltage, Quantity::Length]
        .into_iter()
        .find(|q| q.units().iter().any(|(n, _)| *n == unit))
}

/// A header name as `(name, unit)`: `name [unit]` and `name (unit)` always carry a unit,
/// `name_unit` only when `unit` is an accepted one (else `_` is part of the name).
pub fn split_unit(header: &str) -> (&str, Option<&str>) {
    let h = header.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let Some(inner) = h.strip_suffix(close) {
            if let Some(i) = inner.rfind(open) {
                let (name, unit) = (inner[..i].trim(), inner[i + 1..].trim());
                if !name.is_empty() {
                    return (name, Some(unit));
                }
            }
        }
    }
    if let Some(i) = h.rfind('_') {
        let (name, unit) = (&h[..i], &h[i + 1..]);
        if !name.is_empty() && quantity_of(unit).is_some() {
            return (name, Some(unit));
        }
    }
    (h, None)
}
