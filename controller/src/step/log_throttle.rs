//! A rate limit for log lines that another node on the bus can trigger frame by frame (an address
//! claim from an intruder, a fault in listen-only mode): every such frame is still counted, but a
//! node flooding the bus must not flood the log with it.

/// Shortest time between two log lines of one kind, s.
pub const LOG_INTERVAL_S: f64 = 1.0;

/// Lets the first event of a kind be logged, then at most one per [`LOG_INTERVAL_S`], and counts
/// the events it held back in between (the next line reports them).
///
/// The times come from frames and the controller's clock; a time that is not finite is held back
/// (after the first line), and one more than an interval before the last line (a clock set back)
/// starts the interval again.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LogThrottle {
    last_s: Option<f64>,
    held_back: u64,
}

impl LogThrottle {
    /// Whether an event at `now_s` is logged: `Some(n)` with the `n` events held back since the
    /// last line, or `None` (counted as held back).
    pub fn allow(&mut self, now_s: f64) -> Option<u64> {
        let due = match self.last_s {
            None => true,
            Some(last) => {
                now_s.is_finite()
                    && (now_s >= last + LOG_INTERVAL_S || now_s < last - LOG_INTERVAL_S)
            }
        };
        if due {
            self.last_s = Some(if now_s.is_finite() { now_s } else { 0.0 });
            Some(std::mem::take(&mut self.held_back))
        } else {
            self.held_back += 1;
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flood of 1000 events a second is logged once a second, and each line counts what it
    /// held back.
    #[test]
    fn a_flood_is_logged_once_an_interval_with_the_count_held_back() {
        let mut t = LogThrottle::default();
        let mut lines = Vec::new();
        for k in 0..3000 {
            if let Some(held) = t.allow(f64::from(k) * 0.001) {
                lines.push(held);
            }
        }
        assert_eq!(lines, vec![0, 999, 999]);
    }

    /// Time that is not finite never opens the gate after the first line; a clock set back
    /// opens it again.
    #[test]
    fn bad_time_is_held_back_and_a_clock_set_back_restarts() {
        let mut t = LogThrottle::default();
        assert_eq!(t.allow(100.0), Some(0));
        assert_eq!(t.allow(f64::NAN), None);
        assert_eq!(t.allow(f64::INFINITY), None);
        assert_eq!(t.allow(100.5), None);
        assert_eq!(t.allow(5.0), Some(3));
        assert_eq!(t.allow(5.5), None);
        assert_eq!(t.allow(6.0), Some(1));
        let mut first_nan = LogThrottle::default();
        assert_eq!(first_nan.allow(f64::NAN), Some(0));
        assert_eq!(first_nan.allow(0.5), None);
        assert_eq!(first_nan.allow(1.0), Some(1));
    }
}
