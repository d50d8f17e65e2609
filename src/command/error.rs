//! The protocol's errors and their stable codes.

use core::fmt;

/// Everything that can be wrong with a command line. Codes are stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The line exceeded [`MAX_LINE`](super::MAX_LINE) bytes; it was discarded.
    LineTooLong,
    /// A byte outside printable ASCII.
    NotAscii,
    /// The first word is not a command.
    UnknownCommand,
    /// A required argument is missing.
    MissingArgument,
    /// More arguments than the command takes.
    TooManyArguments,
    /// An argument is not a finite number (or not a non-negative integer where one is needed).
    BadNumber,
    /// No parameter of that name.
    UnknownParam,
    /// The value is outside the parameter's range.
    OutOfRange,
    /// No feedback law / feedforward compensator of that name.
    UnknownMode,
    /// No signal of that name, or no such recorder channel.
    UnknownSignal,
    /// A sub-command word is not one the command knows.
    BadKeyword,
    /// The command is valid but cannot run now (e.g. reading a recorder while it records).
    Busy,
    /// This board does not implement the command.
    Unsupported,
    /// A number with more than [`MAX_DIGITS`](super::MAX_DIGITS) significant digits.
    TooManyDigits,
    /// `load`: the flash holds no settings record.
    NoSettings,
    /// `load`: the stored record is damaged or of another version; nothing was changed.
    BadSettings,
    /// The settings flash failed (erase/program/read error).
    Flash,
    /// The law with this feedforward does not fit the control period at this rate
    /// ([`crate::firmware::Budget`]); nothing changed.
    OverBudget,
}

impl Error {
    /// Every error, in code order: hosts map a reply's code back with [`Error::from_code`].
    /// A new variant breaks the exhaustive match of [`Error::is_listed`] until it is added here.
    pub const ALL: [Error; 18] = {
        use Error::*;
        [
            LineTooLong,
            NotAscii,
            UnknownCommand,
            MissingArgument,
            TooManyArguments,
            BadNumber,
            UnknownParam,
            OutOfRange,
            UnknownMode,
            UnknownSignal,
            BadKeyword,
            Busy,
            Unsupported,
            TooManyDigits,
            NoSettings,
            BadSettings,
            Flash,
            OverBudget,
        ]
    };

    /// The error of a numbered reply code.
    pub fn from_code(code: u8) -> Option<Error> {
        Self::ALL.into_iter().find(|e| e.code() == code)
    }

    /// Compile-time reminder: every variant named here must be in [`Error::ALL`].
    #[allow(dead_code)]
    const fn is_listed(self) {
        use Error::*;
        match self {
            LineTooLong | NotAscii | UnknownCommand | MissingArgument | TooManyArguments
            | BadNumber | UnknownParam | OutOfRange | UnknownMode | UnknownSignal | BadKeyword
            | Busy | Unsupported | TooManyDigits | NoSettings | BadSettings | Flash
            | OverBudget => {}
        }
    }

    /// Stable numeric code sent in `err <code> <message>`.
    pub fn code(self) -> u8 {
        match self {
            Error::LineTooLong => 1,
            Error::NotAscii => 2,
            Error::UnknownCommand => 3,
            Error::MissingArgument => 4,
            Error::TooManyArguments => 5,
            Error::BadNumber => 6,
            Error::UnknownParam => 7,
            Error::OutOfRange => 8,
            Error::UnknownMode => 9,
            Error::UnknownSignal => 10,
            Error::BadKeyword => 11,
            Error::Busy => 12,
            Error::Unsupported => 13,
            Error::TooManyDigits => 14,
            Error::NoSettings => 15,
            Error::BadSettings => 16,
            Error::Flash => 17,
            Error::OverBudget => 18,
        }
    }

    /// Human-readable message (one line, no trailing newline).
    pub fn message(self) -> &'static str {
        match self {
            Error::LineTooLong => "line too long (max 96 bytes)",
            Error::NotAscii => "non-ASCII or control byte in line",
            Error::UnknownCommand => "unknown command (try help)",
            Error::MissingArgument => "missing argument",
            Error::TooManyArguments => "too many arguments",
            Error::BadNumber => "argument is not a finite number",
            Error::UnknownParam => "unknown parameter",
            Error::OutOfRange => "value out of range",
            Error::UnknownMode => "unknown mode name",
            Error::UnknownSignal => "unknown signal or channel",
            Error::BadKeyword => "unknown sub-command",
            Error::Busy => "not possible in the current state",
            Error::Unsupported => "not supported on this board",
            Error::TooManyDigits => "number has more than 19 significant digits",
            Error::NoSettings => "no settings stored",
            Error::BadSettings => "stored settings damaged or stale; nothing changed",
            Error::Flash => "settings flash failed",
            Error::OverBudget => "mode does not fit the control period at this rate",
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "err {} {}", self.code(), self.message())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_one_to_n_in_list_order() {
        for (i, e) in Error::ALL.into_iter().enumerate() {
            assert_eq!(usize::from(e.code()), i + 1, "{e:?}");
            assert_eq!(Error::from_code(e.code()), Some(e));
        }
        assert_eq!(Error::from_code(0), None);
    }
}
