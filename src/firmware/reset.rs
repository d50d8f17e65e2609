//! The STM32H7's reset cause from its `RCC_RSR` flags (RM0433, "Reset source
//! identification"): a reset sets several flags at once (a power-on reset sets PORRSTF,
//! BORRSTF, PINRSTF, D1RSTF, D2RSTF and CPURSTF; a brown-out BORRSTF, PINRSTF and CPURSTF;
//! every system reset PINRSTF), so the cause is the most specific flag set: the watchdogs,
//! software and low-power resets first, then power-on before brown-out, then the pin.

/// `RCC_RSR` flags (RM0433).
pub const CPURSTF: u32 = 1 << 17;
pub const D1RSTF: u32 = 1 << 19;
pub const D2RSTF: u32 = 1 << 20;
pub const BORRSTF: u32 = 1 << 21;
pub const PINRSTF: u32 = 1 << 22;
pub const PORRSTF: u32 = 1 << 23;
pub const SFTRSTF: u32 = 1 << 24;
pub const IWDG1RSTF: u32 = 1 << 26;
pub const WWDG1RSTF: u32 = 1 << 28;
pub const LPWRRSTF: u32 = 1 << 30;

/// The reset cause of the flags `rsr`.
pub fn reset_cause(rsr: u32) -> &'static str {
    const CAUSES: [(u32, &str); 8] = [
        (LPWRRSTF, "low-power"),
        (WWDG1RSTF, "window-watchdog"),
        (IWDG1RSTF, "independent-watchdog"),
        (SFTRSTF, "software"),
        (PORRSTF, "power-on"),
        (BORRSTF, "brown-out"),
        (PINRSTF, "pin"),
        (CPURSTF, "cpu"),
    ];
    CAUSES
        .iter()
        .find(|(bit, _)| rsr & bit != 0)
        .map_or("unknown", |(_, name)| name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flag combinations of RM0433's reset source table.
    #[test]
    fn each_reset_of_the_table_decodes_to_its_cause() {
        let sys = PINRSTF | CPURSTF;
        for (flags, cause) in [
            (PORRSTF | BORRSTF | D1RSTF | D2RSTF | sys, "power-on"),
            (BORRSTF | sys, "brown-out"),
            (sys, "pin"),
            (SFTRSTF | sys, "software"),
            (IWDG1RSTF | sys, "independent-watchdog"),
            (WWDG1RSTF | sys, "window-watchdog"),
            (LPWRRSTF | sys, "low-power"),
            (CPURSTF, "cpu"),
            (0, "unknown"),
        ] {
            assert_eq!(reset_cause(flags), cause, "{flags:#x}");
        }
    }
}
