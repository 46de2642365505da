//! Shared code of the runnable examples. Each example's logic lives here as
//! a module (its files next to the example's `main.rs`) so that the tests
//! package can run it in-process.

#[path = "../mixture/mod.rs"]
pub mod mixture;

#[path = "../posteriordb/mod.rs"]
pub mod posteriordb;

/// The code blocks of `docs/user-guide.md`, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../../docs/user-guide.md")]
pub struct UserGuide;
