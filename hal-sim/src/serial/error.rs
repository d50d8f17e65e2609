//! Why a command failed; the firmware's numbered errors mapped back to their meaning.
use std::fmt;
use std::io;
use std::time::Duration;

use piezo_core::command;

/// Every protocol error, for mapping a reply's code back to its meaning. The match below
/// fails to compile when the firmware gains an error the host does not list.
pub const ERRORS: [command::Error; 17] = {
    use command::Error::*;
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
    ]
};

#[allow(dead_code)]
fn errors_are_listed(e: command::Error) {
    use command::Error::*;
    match e {
        LineTooLong | NotAscii | UnknownCommand | MissingArgument | TooManyArguments
        | BadNumber | UnknownParam | OutOfRange | UnknownMode | UnknownSignal | BadKeyword
        | Busy | Unsupported | TooManyDigits | NoSettings | BadSettings | Flash => {}
    }
}

/// The protocol error of a numbered reply code.
pub fn known_error(code: u8) -> Option<command::Error> {
    ERRORS.into_iter().find(|e| e.code() == code)
}

/// Why a command failed.
#[derive(Debug)]
pub enum SerialError {
    /// The firmware answered `err <code> <message>`.
    Firmware {
        command: String,
        code: Option<u8>,
        message: String,
    },
    /// No complete reply line within the timeout.
    Timeout {
        command: String,
        after: Duration,
    },
    /// The other end closed the connection.
    Closed {
        command: String,
    },
    /// A reply the host cannot use.
    BadReply {
        command: String,
        line: String,
        why: String,
    },
    /// A command line the host refuses to send.
    BadCommand {
        command: String,
        why: String,
    },
    Io {
        command: String,
        source: io::Error,
    },
}

impl fmt::Display for SerialError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SerialError::Firmware {
                command,
                code,
                message,
            } => {
                match code {
                    Some(c) => write!(f, "`{command}`: firmware error {c}: {message}")?,
                    None => write!(f, "`{command}`: firmware error (no code): {message}")?,
                }
                match code.and_then(known_error) {
                    Some(e) => write!(f, " ({e:?})"),
                    None => write!(f, " (a code this host does not know)"),
                }
            }
            SerialError::Timeout { command, after } => write!(
                f,
                "`{command}`: no reply within {:.1} s (firmware running? right port and baud rate?)",
                after.as_secs_f64()
            ),
            SerialError::Closed { command } => write!(
                f,
                "`{command}`: connection closed before the reply (firmware exited or reset?)"
            ),
            SerialError::BadReply { command, line, why } => {
                write!(f, "`{command}`: unusable reply `{line}`: {why}")
            }
            SerialError::BadCommand { command, why } => {
                write!(f, "`{command}`: not sent: {why}")
            }
            SerialError::Io { command, source } => write!(f, "`{command}`: {source}"),
        }
    }
}

// The I/O error's text is part of the message already, so no `source`.
impl std::error::Error for SerialError {}

/// A hang-up is [`SerialError::Closed`]; other I/O errors keep their text.
pub(crate) fn io_err(command: &str, source: io::Error) -> SerialError {
    use io::ErrorKind::*;
    match source.kind() {
        ConnectionReset | ConnectionAborted | BrokenPipe | UnexpectedEof => SerialError::Closed {
            command: command.into(),
        },
        _ => SerialError::Io {
            command: command.into(),
            source,
        },
    }
}
