//! The command line's output streams, written without panicking.
//!
//! `println!` panics when standard output cannot be written (a closed
//! pipe, as in `mcmc-render compare A B | head -1`, or a full device).
//! Every report line of the subcommands goes through [`out!`] instead,
//! which returns the failure: a closed pipe ends the command quietly with
//! status 0 (the reader has taken all it wanted, as `head` does; a status
//! other than 0 would fail a `set -o pipefail` script for nothing), any
//! other write error is one `error:` line and status 1. Lines on standard
//! error go through [`err!`], which ignores failures: there is nowhere
//! left to report them.

use std::fmt;
use std::io::{self, Write};

/// Why a subcommand stopped before finishing.
#[derive(Debug)]
pub enum Failure {
    /// Standard output was closed by its reader: exit quietly, status 0.
    StdoutClosed,
    /// A one-line message for `error: …`, status 1.
    Message(String),
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure::Message(s)
    }
}

impl From<&str> for Failure {
    fn from(s: &str) -> Self {
        Failure::Message(s.to_string())
    }
}

/// Writes `args` to standard output and flushes it, so that a closed pipe
/// is seen at the line that meets it (the caller then stops).
pub fn print(args: fmt::Arguments<'_>) -> Result<(), Failure> {
    let mut out = io::stdout().lock();
    out.write_fmt(args)
        .and_then(|()| out.flush())
        .map_err(|e| match e.kind() {
            io::ErrorKind::BrokenPipe => Failure::StdoutClosed,
            _ => Failure::Message(format!("cannot write to standard output: {e}")),
        })
}

/// Writes `args` to standard error, ignoring a failure (a closed or full
/// standard error leaves nowhere to report it).
pub fn eprint(args: fmt::Arguments<'_>) {
    let _ = io::stderr().lock().write_fmt(args);
}

/// `println!` that returns `Result<(), Failure>` instead of panicking.
macro_rules! out {
    () => {
        $crate::cli::stdout::print(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::stdout::print(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `eprintln!` that ignores a failure to write instead of panicking.
macro_rules! err {
    ($($arg:tt)*) => {
        $crate::cli::stdout::eprint(format_args!("{}\n", format_args!($($arg)*)))
    };
}

pub(crate) use {err, out};
