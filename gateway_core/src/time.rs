//! The gateway's clock: integer nanoseconds, so the firmware needs no floating-point time (a
//! microcontroller counts timer ticks; `f64` seconds lose resolution as they grow and cost soft-float
//! on a single-precision FPU).
//!
//! [`Instant`] is a reading of a monotonic clock. The gateway's methods take a [`ClockReading`]: an
//! [`Instant`] from a hardware timer, or `f64` seconds from a host clock (the simulator's), converted
//! here and *unreadable* when not finite or beyond the range of an [`Instant`]. The gateway checks the
//! readings it gets (`gateway` module docs, "Time"): an unreadable one latches a clock fault.

/// Nanoseconds per second.
pub const NANOS_PER_S: i64 = 1_000_000_000;

/// A reading of a monotonic clock: nanoseconds since an arbitrary epoch (boot, or the start of a
/// simulation). `i64` covers 292 years either side of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Instant(i64);

impl Instant {
    /// The epoch.
    pub const ZERO: Self = Self(0);

    /// `nanos` nanoseconds after the epoch.
    pub const fn from_nanos(nanos: i64) -> Self {
        Self(nanos)
    }

    /// `micros` microseconds after the epoch (saturating at the range of an [`Instant`]).
    pub const fn from_micros(micros: i64) -> Self {
        Self(micros.saturating_mul(1_000))
    }

    /// `millis` milliseconds after the epoch (saturating at the range of an [`Instant`]).
    pub const fn from_millis(millis: i64) -> Self {
        Self(millis.saturating_mul(1_000_000))
    }

    /// `s` seconds after the epoch, rounded to the nearest nanosecond; `None` if `s` is not finite
    /// or outside the range of an [`Instant`].
    pub fn from_secs_f64(s: f64) -> Option<Self> {
        secs_to_nanos(s).map(Self)
    }

    /// Nanoseconds since the epoch.
    pub const fn nanos(self) -> i64 {
        self.0
    }

    /// Seconds since the epoch.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 / NANOS_PER_S as f64
    }

    /// `self - earlier` in nanoseconds (negative if `earlier` is later; saturating).
    pub const fn nanos_since(self, earlier: Self) -> i64 {
        self.0.saturating_sub(earlier.0)
    }
}

/// `s` seconds as nanoseconds, rounded; `None` if not finite or beyond `i64`.
pub fn secs_to_nanos(s: f64) -> Option<i64> {
    // 2^63 ns: the first value past the range of i64 (exact in f64).
    const LIMIT: f64 = 9_223_372_036_854_775_808.0;
    let ns = libm::round(s * NANOS_PER_S as f64);
    (ns.is_finite() && (-LIMIT..LIMIT).contains(&ns)).then_some(ns as i64)
}

/// A time handed to the gateway: an [`Instant`], or `None` when the clock could not be read (a
/// non-finite `f64`). Build it with `From`: `Instant` or `f64` seconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockReading(pub Option<Instant>);

impl From<Instant> for ClockReading {
    fn from(t: Instant) -> Self {
        Self(Some(t))
    }
}

impl From<f64> for ClockReading {
    fn from(s: f64) -> Self {
        Self(Instant::from_secs_f64(s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_convert_to_the_nearest_nanosecond() {
        assert_eq!(
            Instant::from_secs_f64(0.001),
            Some(Instant::from_micros(1000))
        );
        assert_eq!(
            Instant::from_secs_f64(-2.5),
            Some(Instant::from_millis(-2500))
        );
        // Milliseconds as f64 seconds land on the millisecond grid up to years.
        for k in [1_i64, 999, 1_000_001, 31_557_600_000] {
            let s = k as f64 * 0.001;
            assert_eq!(
                Instant::from_secs_f64(s),
                Some(Instant::from_millis(k)),
                "{k}"
            );
        }
        assert_eq!(Instant::from_millis(1500).as_secs_f64(), 1.5);
    }

    #[test]
    fn unreadable_seconds_are_none() {
        for s in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e10, -1e10] {
            assert_eq!(ClockReading::from(s), ClockReading(None), "{s}");
        }
        assert_eq!(
            ClockReading::from(9.2e9),
            ClockReading(Some(Instant::from_nanos(9_200_000_000_000_000_000)))
        );
    }
}
