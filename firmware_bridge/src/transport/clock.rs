//! Bus clocks: the wall clock, or a virtual clock the simulation sets.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use tokio::sync::Notify;

/// A shared virtual clock in nanoseconds, set by the simulation (cheap to clone; clones share the
/// time). Time never goes backwards: [`VirtualClock::set_ns`] ignores earlier times.
#[derive(Debug, Clone, Default)]
pub struct VirtualClock {
    inner: Arc<VirtualInner>,
}

#[derive(Debug, Default)]
struct VirtualInner {
    now_ns: AtomicU64,
    changed: Notify,
}

impl VirtualClock {
    /// A clock at time zero.
    pub fn new() -> Self {
        Self::default()
    }

    /// Current time, nanoseconds.
    pub fn now_ns(&self) -> u64 {
        self.inner.now_ns.load(Ordering::Acquire)
    }

    /// Current time, seconds.
    pub fn now_s(&self) -> f64 {
        self.now_ns() as f64 * 1e-9
    }

    /// Sets the time (ignored if earlier than now) and wakes tasks waiting for delayed frames.
    pub fn set_ns(&self, ns: u64) {
        self.inner.now_ns.fetch_max(ns, Ordering::AcqRel);
        self.inner.changed.notify_waiters();
    }

    /// Advances the time by `dt_ns`.
    pub fn advance_ns(&self, dt_ns: u64) {
        self.inner.now_ns.fetch_add(dt_ns, Ordering::AcqRel);
        self.inner.changed.notify_waiters();
    }

    pub(crate) fn changed(&self) -> tokio::sync::futures::Notified<'_> {
        self.inner.changed.notified()
    }
}

/// The time source of a bus.
#[derive(Debug, Clone, Default)]
pub enum Clock {
    /// Wall clock: nanoseconds since the Unix epoch.
    #[default]
    Wall,
    /// A virtual clock set by the simulation.
    Virtual(VirtualClock),
}

impl Clock {
    /// Current time, nanoseconds.
    pub fn now_ns(&self) -> u64 {
        match self {
            Self::Wall => wall_now_ns(),
            Self::Virtual(v) => v.now_ns(),
        }
    }
}

/// Wall-clock nanoseconds since the Unix epoch (0 if the system clock is before 1970).
pub fn wall_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_clock_is_shared_and_monotonic() {
        let clock = VirtualClock::new();
        let other = clock.clone();
        clock.set_ns(1_000);
        other.advance_ns(500);
        assert_eq!(clock.now_ns(), 1_500);
        clock.set_ns(10);
        assert_eq!(clock.now_ns(), 1_500);
        assert!(Clock::Wall.now_ns() > 1_600_000_000_000_000_000);
    }
}

/// How many times faster than real time a bus session runs (the simulator and the controller must
/// agree: `excavator-sim --time-scale` and `excavator-ctl run --time-scale`). 1 is real time; the
/// accepted range is [`TimeScale::MIN`] to [`TimeScale::MAX`].
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct TimeScale(f64);

/// A time scale outside the accepted range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("time scale {0}: expected a number from {min} to {max}", min = TimeScale::MIN, max = TimeScale::MAX)]
pub struct TimeScaleError(pub String);

impl TimeScale {
    /// Real time.
    pub const REAL_TIME: Self = Self(1.0);
    /// The slowest accepted scale.
    pub const MIN: f64 = 0.1;
    /// The fastest accepted scale: a 10 ms control period is then 0.5 ms of wall time.
    pub const MAX: f64 = 20.0;

    /// A checked scale.
    ///
    /// # Errors
    /// [`TimeScaleError`] when `x` is not finite or outside [`Self::MIN`]..=[`Self::MAX`].
    pub fn new(x: f64) -> std::result::Result<Self, TimeScaleError> {
        if x.is_finite() && (Self::MIN..=Self::MAX).contains(&x) {
            Ok(Self(x))
        } else {
            Err(TimeScaleError(x.to_string()))
        }
    }

    /// The factor.
    pub fn get(self) -> f64 {
        self.0
    }
}

impl Default for TimeScale {
    fn default() -> Self {
        Self::REAL_TIME
    }
}

impl std::fmt::Display for TimeScale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::str::FromStr for TimeScale {
    type Err = TimeScaleError;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let x: f64 = s.trim().parse().map_err(|_| TimeScaleError(s.to_owned()))?;
        Self::new(x)
    }
}

#[cfg(test)]
mod time_scale_tests {
    use super::*;

    #[test]
    fn time_scales_are_checked() {
        assert_eq!("1".parse::<TimeScale>(), Ok(TimeScale::REAL_TIME));
        assert_eq!("20".parse::<TimeScale>().map(TimeScale::get), Ok(20.0));
        assert_eq!(" 0.1 ".parse::<TimeScale>().map(TimeScale::get), Ok(0.1));
        for bad in ["0", "-1", "20.5", "NaN", "inf", "", "fast", "0.09"] {
            let e = bad.parse::<TimeScale>().unwrap_err();
            assert!(e.to_string().contains("from 0.1 to 20"), "{bad}: {e}");
        }
        assert_eq!(TimeScale::default(), TimeScale::REAL_TIME);
    }
}
