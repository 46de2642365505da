//! Stan's warm-up windows.

/// Stan's warm-up schedule: iterations `[0, init)` adapt only the step size,
/// slow windows in `[init, n − term)` (lengths 25, 50, 100, …, the last one
/// stretched to the terminal buffer) also estimate the metric, and
/// `[n − term, n)` adapts the step size to the final metric.
///
/// ```
/// use mcmc_core::adaptation::WarmupSchedule;
/// let s = WarmupSchedule::stan(1000);
/// assert_eq!(s.window_ends(), vec![99, 149, 249, 449, 949]);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WarmupSchedule {
    iterations: usize,
    init_buffer: usize,
    term_buffer: usize,
    ends: Vec<usize>,
}

impl WarmupSchedule {
    /// Stan's defaults (75 / 25 / 50) for `iterations` warm-up steps; when
    /// they do not fit, Stan's fallback of 15 % / 75 % / 10 %. Under 20
    /// iterations there are no slow windows.
    pub fn stan(iterations: usize) -> Self {
        Self::new(iterations, 75, 25, 50)
    }

    /// Stan's buffers stretched in proportion to the warm-up length: for
    /// `iterations = n ≥ 1000`, an initial buffer of 7.5 % of `n`, a first
    /// slow window of 2.5 % and a terminal buffer of 5 % (Stan's 75 / 25 /
    /// 50 at `n = 1000`, and Stan's schedule below). Stan's fixed lengths
    /// assume nearly independent draws (NUTS); a kernel whose draws are
    /// strongly autocorrelated (MALA: tens to hundreds of iterations per
    /// independent draw in 100 dimensions) needs windows that grow with the
    /// warm-up for its variance estimates and its final step size to settle.
    ///
    /// ```
    /// use mcmc_core::adaptation::WarmupSchedule;
    /// assert_eq!(WarmupSchedule::proportional(1000), WarmupSchedule::stan(1000));
    /// assert_eq!(WarmupSchedule::proportional(10_000).window_ends(), vec![999, 1499, 2499, 4499, 9499]);
    /// ```
    pub fn proportional(iterations: usize) -> Self {
        let f = iterations.max(1000) as f64 / 1000.0;
        Self::new(
            iterations,
            (75.0 * f) as usize,
            (25.0 * f) as usize,
            (50.0 * f) as usize,
        )
    }

    /// A schedule with the given buffers and base window. A base window of
    /// 0 is taken as 1 (a window must hold an iteration; with 0 the
    /// doubling never advanced and the window list grew until memory ran
    /// out); buffers that do not fit fall back to Stan's 15% / 75% / 10%.
    pub fn new(iterations: usize, init: usize, base: usize, term: usize) -> Self {
        let (mut init, mut base, mut term) = (init, base.max(1), term);
        if iterations < 20 {
            return WarmupSchedule {
                iterations,
                init_buffer: iterations,
                term_buffer: 0,
                ends: Vec::new(),
            };
        }
        if init.saturating_add(base).saturating_add(term) > iterations {
            init = (0.15 * iterations as f64) as usize;
            term = (0.1 * iterations as f64) as usize;
            base = iterations - (init + term);
        }
        let slow_end = iterations - term; // first terminal iteration
        let mut ends = Vec::new();
        let mut window = base;
        let mut end = init + base - 1;
        loop {
            if end + 1 >= slow_end {
                ends.push(slow_end - 1);
                break;
            }
            // Stretch this window when the next (doubled) one would not fit.
            if end + 1 + 2 * window > slow_end {
                ends.push(slow_end - 1);
                break;
            }
            ends.push(end);
            window *= 2;
            end += window;
        }
        WarmupSchedule {
            iterations,
            init_buffer: init,
            term_buffer: term,
            ends,
        }
    }

    /// Warm-up length.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// First iteration of the last slow window (`None` without slow
    /// windows).
    pub fn last_window_start(&self) -> Option<usize> {
        match self.ends.len() {
            0 => None,
            1 => Some(self.init_buffer),
            n => Some(self.ends[n - 2] + 1),
        }
    }

    /// Last iteration of the slow windows before the last two (`None` with
    /// fewer than three windows): where
    /// [`MetricAdaptation::DiagonalGradientEarly`](super::MetricAdaptation::DiagonalGradientEarly)
    /// switches to the variances.
    pub fn early_windows_end(&self) -> Option<usize> {
        self.ends.len().checked_sub(3).map(|k| self.ends[k])
    }

    /// True when iteration `i` (0-based) belongs to a slow window.
    pub fn in_slow_window(&self, i: usize) -> bool {
        !self.ends.is_empty() && i >= self.init_buffer && i < self.iterations - self.term_buffer
    }

    /// True when iteration `i` ends a slow window (the metric is updated).
    pub fn is_window_end(&self, i: usize) -> bool {
        self.ends.contains(&i)
    }

    /// The iterations that end slow windows.
    pub fn window_ends(&self) -> Vec<usize> {
        self.ends.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (found by `constructor_proptests`): a zero base window
    /// and buffers near `usize::MAX` give a finite, valid schedule.
    #[test]
    fn degenerate_windows_give_a_valid_schedule() {
        for (init, base, term) in [(0, 0, 0), (10, 0, 10), (usize::MAX, 5, usize::MAX)] {
            let s = WarmupSchedule::new(1000, init, base, term);
            assert!(!s.window_ends().is_empty() && s.window_ends().len() < 64);
            assert!(s.window_ends().iter().all(|&e| e < 1000));
        }
    }

    #[test]
    fn stan_windows_for_default_and_short_warmups() {
        // Stan's default 1000: 75 + 25 + 50 + 100 + 200 + 500 (stretched) + 50.
        let s = WarmupSchedule::stan(1000);
        assert!(!s.in_slow_window(74) && s.in_slow_window(75));
        assert_eq!(s.last_window_start(), Some(450));
        assert_eq!(s.early_windows_end(), Some(249));
        assert!(s.in_slow_window(949) && !s.in_slow_window(950));
        // 100 < 150: fallback 15 % / 75 % / 10 %, one slow window [15, 90).
        let s = WarmupSchedule::stan(100);
        assert_eq!(s.window_ends(), vec![89]);
        assert_eq!(s.last_window_start(), Some(15));
        assert_eq!(s.early_windows_end(), None);
        assert!(!s.in_slow_window(14) && s.in_slow_window(15) && !s.in_slow_window(90));
        // Under 20 iterations: step size only.
        let s = WarmupSchedule::stan(10);
        assert!(s.window_ends().is_empty());
        assert_eq!(s.last_window_start(), None);
        assert!((0..10).all(|i| !s.in_slow_window(i)));
    }
}
