//! Cross-crate and statistical tests live in this package's test targets.
