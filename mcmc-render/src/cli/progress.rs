//! The progress bar with ETA and the periodic PNG preview of `render`.

use crate::color::Rgb;
use crate::image_io::write_png;
use crate::observer::Observer;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How often the preview PNG is rewritten at most.
const PREVIEW_EVERY: Duration = Duration::from_secs(5);

/// Progress bar and periodic previews of one render.
pub struct CliObserver {
    bar: ProgressBar,
    /// Counting time (ms of the budget) instead of samples.
    budget: Option<Duration>,
    start: Instant,
    preview: PathBuf,
    size: (u32, u32),
    last_preview: Mutex<Instant>,
}

impl CliObserver {
    /// A bar over `work` samples, or over the time `budget` when the work
    /// is open-ended; hidden when `quiet`.
    pub fn new(
        work: Option<u64>,
        budget: Option<Duration>,
        quiet: bool,
        preview: PathBuf,
        size: (u32, u32),
    ) -> Self {
        let (bar, budget) = if quiet {
            (ProgressBar::hidden(), None)
        } else {
            match (work, budget) {
                (Some(n), _) => (ProgressBar::new(n), None),
                (None, Some(b)) => (ProgressBar::new(b.as_millis() as u64), Some(b)),
                (None, None) => (ProgressBar::new(0), None),
            }
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% ETA {eta} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        CliObserver {
            bar,
            budget,
            start: Instant::now(),
            preview,
            size,
            last_preview: Mutex::new(Instant::now()),
        }
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Observer for CliObserver {
    fn progress(&self, n: u64) {
        match self.budget {
            Some(b) => self
                .bar
                .set_position((self.start.elapsed().as_millis() as u64).min(b.as_millis() as u64)),
            None => self.bar.inc(n),
        }
    }

    fn snapshot(&self, image: &dyn Fn() -> Vec<Rgb>, samples: u64) {
        self.bar.set_message(format!("{samples} samples"));
        let mut last = self.last_preview.lock().unwrap_or_else(|p| p.into_inner());
        if last.elapsed() >= PREVIEW_EVERY {
            *last = Instant::now();
            // A failed preview must not stop the render; the final write reports errors.
            let _ = write_png(&self.preview, self.size.0, self.size.1, &image());
        }
    }
}
