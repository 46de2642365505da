//! The example's one error type: a one-line message and the exit code.

use std::fmt;

/// Exit code for invalid flags or target files (clap uses 2 for usage errors too).
pub const USAGE_EXIT_CODE: i32 = 2;
/// Exit code for failures while sampling (e.g. every start-up candidate had zero density).
pub const RUN_EXIT_CODE: i32 = 1;

/// A failure of the example: what to print (one line) and how to exit.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExampleError {
    /// Process exit code: [`USAGE_EXIT_CODE`] or [`RUN_EXIT_CODE`].
    pub code: i32,
    /// One line, without a trailing newline.
    pub message: String,
}

impl ExampleError {
    /// Invalid flags or target file: exit code 2.
    pub fn usage(message: impl Into<String>) -> Self {
        ExampleError {
            code: USAGE_EXIT_CODE,
            message: one_line(message.into()),
        }
    }

    /// A failure while running: exit code 1.
    pub fn run(message: impl Into<String>) -> Self {
        ExampleError {
            code: RUN_EXIT_CODE,
            message: one_line(message.into()),
        }
    }

    /// A clap parse error, reduced to its first line; clap's own exit code
    /// (2 for usage errors) is kept.
    pub fn from_clap(e: &clap::Error) -> Self {
        // clap's first paragraph holds the error (e.g. "the following required
        // arguments were not provided:" and the arguments on the next lines);
        // the usage and tips follow after a blank line.
        let rendered = e.render().to_string();
        let paragraph: Vec<&str> = rendered
            .lines()
            .map(str::trim)
            .skip_while(|l| l.is_empty())
            .take_while(|l| !l.is_empty())
            .collect();
        let line = paragraph.join(" ");
        let line = line.strip_prefix("error: ").unwrap_or(&line);
        ExampleError {
            code: e.exit_code(),
            message: if line.is_empty() {
                "invalid arguments".into()
            } else {
                line.to_string()
            },
        }
    }
}

/// Joins the lines of a message so the error stays on one line.
fn one_line(s: String) -> String {
    if s.contains('\n') {
        s.lines().map(str::trim).collect::<Vec<_>>().join(" ")
    } else {
        s
    }
}

impl fmt::Display for ExampleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "error: {}", self.message)
    }
}

impl std::error::Error for ExampleError {}
