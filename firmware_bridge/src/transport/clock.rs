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
