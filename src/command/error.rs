//! The protocol's errors and their stable codes.

use core::fmt;

/// Declares [`Error`] from one table: variant, stable code, message. The enum, its
/// [`Error::ALL`] list, [`Error::code`] and [`Error::message`] come from the same rows, so a
/// new error cannot be left out of one of them.
macro_rules! errors {
    ($($(#[doc = $doc:expr])* $v:ident = $code:literal => $msg:literal,)*) => {
        /// Everything that can be wrong with a command line. Codes are stable.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Error {
            $($(#[doc = $doc])* $v,)*
        }

        impl Error {
            /// Every error, in code order: hosts map a reply's code back with
            /// [`Error::from_code`].
            pub const ALL: [Error; [$($code),*].len()] = [$(Error::$v),*];

            /// Stable numeric code sent in `err <code> <message>`.
            pub fn code(self) -> u8 {
                match self {
                    $(Error::$v => $code,)*
                }
            }

            /// Human-readable message (one line, no trailing newline).
            pub fn message(self) -> &'static str {
                match self {
                    $(Error::$v => $msg,)*
                }
            }
        }
    };
}

errors! {
    /// The line exceeded [`MAX_LINE`](super::MAX_LINE) bytes; it was discarded.
    LineTooLong = 1 => "line too long (max 96 bytes)",
    /// A byte outside printable ASCII.
    NotAscii = 2 => "non-ASCII or control byte in line",
    /// The first word is not a command.
    UnknownCommand = 3 => "unknown command (try help)",
    /// A required argument is missing.
    MissingArgument = 4 => "missing argument",
    /// More arguments than the command takes.
    TooManyArguments = 5 => "too many arguments",
    /// An argument is not a finite number (or not a non-negative integer where one is needed).
    BadNumber = 6 => "argument is not a finite number",
    /// No parameter of that name.
    UnknownParam = 7 => "unknown parameter",
    /// The value is outside the parameter's range.
    OutOfRange = 8 => "value out of range",
    /// No feedback law / feedforward compensator of that name.
    UnknownMode = 9 => "unknown mode name",
    /// No signal of that name, or no such recorder channel.
    UnknownSignal = 10 => "unknown signal or channel",
    /// A sub-command word is not one the command knows.
    BadKeyword = 11 => "unknown sub-command",
    /// The command is valid but cannot run now (e.g. reading a recorder while it records).
    Busy = 12 => "not possible in the current state",
    /// This board does not implement the command.
    Unsupported = 13 => "not supported on this board",
    /// A number with more than [`MAX_DIGITS`](super::MAX_DIGITS) significant digits.
    TooManyDigits = 14 => "number has more than 19 significant digits",
    /// `load`: the flash holds no settings record.
    NoSettings = 15 => "no settings stored",
    /// `load`: the stored record is damaged or of another version; nothing was changed.
    BadSettings = 16 => "stored settings damaged or stale; nothing changed",
    /// The settings flash failed (erase/program/read error).
    Flash = 17 => "settings flash failed",
    /// The law with this feedforward does not fit the control period at this rate ([`crate::firmware::Budget`]); nothing changed.
    OverBudget = 18 => "mode does not fit the control period at this rate",
}

impl Error {
    /// The error of a numbered reply code.
    pub fn from_code(code: u8) -> Option<Error> {
        Self::ALL.into_iter().find(|e| e.code() == code)
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
