//! Why a configuration could not be loaded: always with the key, and where the value was
//! set (`FILE:LINE:COL`, `env VAR`, `command line`), as `WHERE: KEY: MESSAGE`.

use std::path::PathBuf;

use super::Origin;
use super::check::Invalid;
use super::env::EnvError;
use super::origin::SyntaxError;

/// A configuration that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file (or `auth.keys_file`) could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not TOML.
    #[error(transparent)]
    Syntax(#[from] SyntaxError),
    /// A value of the wrong type, or an unknown key.
    #[error("{origin}: {key}: {message}")]
    Parse {
        /// Where the value was set (for an unknown key: the key itself); boxed to keep
        /// results small.
        origin: Box<Origin>,
        /// The key.
        key: String,
        /// What is wrong, in the reader's words.
        message: String,
    },
    /// Values that are valid alone but cannot be run.
    #[error("{origin}: {key}: {source}")]
    Invalid {
        /// Where the value was set; boxed to keep results small.
        origin: Box<Origin>,
        /// The key.
        key: String,
        /// What is wrong.
        source: Invalid,
    },
    /// A `RACKD_` variable that is refused.
    #[error(transparent)]
    Env(#[from] EnvError),
}
