//! [`CliError`]: why a command failed, by class, as the one line `ribreg` prints on
//! stderr (`ribreg: error: ...`).
//!
//! Every class exits with code 2 (README, "Command line"); the classes say where the
//! failure came from, so callers and tests can tell a bad file from a dropped link.

use std::fmt;
use std::path::{Path, PathBuf};

use ribreg_core::Error;

use crate::hil::emulator::QemuError;
use crate::io::IoError;

/// Why a command failed: one line for stderr.
#[derive(Debug)]
pub enum CliError {
    /// Reading or writing a file failed, or its content is malformed ([`crate::io`]).
    Io(IoError),
    /// The core refused the data (too few points, a degenerate cloud, ...).
    Core(Error),
    /// A file's content or a flag's value that cannot work: what was found and what was
    /// expected, with the file when there is one.
    Input {
        /// The file, when the bad value came from one.
        path: Option<PathBuf>,
        /// What is wrong.
        message: String,
    },
    /// Arguments that cannot work together (a flag that needs another, a path used twice).
    Usage(String),
    /// A result could not be written: an output folder, a report's serialisation, a figure.
    Output(String),
    /// The link to the controller or its protocol: a connection that failed or closed,
    /// messages left unacknowledged, a stage that timed out, a controller fault, a
    /// message lost or applied twice.
    Link(String),
    /// The emulator: QEMU missing, the firmware not built, QEMU failing to start or
    /// exiting, the firmware not exiting cleanly.
    Emulator(QemuError),
    /// A measured figure out of its bound (waypoint error, instruction and stack budgets).
    Tolerance(String),
}

impl CliError {
    /// Bad content of `path`.
    pub fn input(path: &Path, message: impl Into<String>) -> Self {
        CliError::Input {
            path: Some(path.to_path_buf()),
            message: message.into(),
        }
    }

    /// A bad value that came from no file (a flag, a configuration).
    pub fn value(message: impl Into<String>) -> Self {
        CliError::Input {
            path: None,
            message: message.into(),
        }
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Io(e) => write!(f, "{e}"),
            CliError::Core(e) => write!(f, "{e}"),
            CliError::Input {
                path: Some(path),
                message,
            } => write!(f, "{}: {message}", path.display()),
            CliError::Input {
                path: None,
                message,
            } => f.write_str(message),
            CliError::Emulator(e) => write!(f, "{e}"),
            CliError::Usage(s)
            | CliError::Output(s)
            | CliError::Link(s)
            | CliError::Tolerance(s) => f.write_str(s),
        }
    }
}

impl std::error::Error for CliError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            CliError::Io(e) => Some(e),
            CliError::Emulator(e) => Some(e),
            _ => None,
        }
    }
}

impl From<IoError> for CliError {
    fn from(e: IoError) -> Self {
        CliError::Io(e)
    }
}

impl From<Error> for CliError {
    fn from(e: Error) -> Self {
        CliError::Core(e)
    }
}

impl From<QemuError> for CliError {
    fn from(e: QemuError) -> Self {
        CliError::Emulator(e)
    }
}
