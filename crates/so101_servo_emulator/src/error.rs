//! What can go wrong starting or persisting the emulated bus: the pty, its link, the state file,
//! the serving thread.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    #[error("cannot open a pseudo-terminal: {0}")]
    OpenPty(#[source] nix::Error),
    #[error("cannot make the pseudo-terminal raw: {0}")]
    RawMode(#[source] nix::Error),
    #[error("bad link path {path}: {reason}")]
    BadLink { path: PathBuf, reason: String },
    #[error("cannot read state file {path}: {reason}")]
    StateFile { path: PathBuf, reason: String },
    #[error("cannot save state file {path}: {reason}")]
    SaveState { path: PathBuf, reason: String },
    #[error("cannot start the emulator thread: {0}")]
    Thread(#[source] std::io::Error),
}
