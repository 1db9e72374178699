//! The finite-and-range check that every configuration, state file and step input of the workspace
//! shares: [`Limits`], an interval only finite values lie in, and [`OutOfRange`], the rule a value
//! breaks, stated one way (`must be finite and in (0.01, 0.1] s`, `must be finite and > 0`,
//! `must be finite`) whatever error type the caller wraps it in.
//!
//! The callers keep their own errors, which name the file, the line and the field; this module owns
//! only the predicate and the wording of the rule. It allocates nothing, so the gateway's firmware
//! logic can use it too.

use core::fmt;

/// An interval a value must lie in; only finite values lie in one (NaN and the infinities lie in
/// none, not even in [`Limits::FINITE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    lo: f64,
    lo_open: bool,
    hi: f64,
    hi_open: bool,
    unit: &'static str,
}

impl Limits {
    /// Any finite value.
    pub const FINITE: Self = Self::closed(f64::NEG_INFINITY, f64::INFINITY, "");
    /// A finite value above 0.
    pub const POSITIVE: Self = Self::open(0.0, f64::INFINITY, "");
    /// A finite value of at least 0.
    pub const NON_NEGATIVE: Self = Self::closed(0.0, f64::INFINITY, "");

    /// `[lo, hi]`, in `unit` (may be empty).
    pub const fn closed(lo: f64, hi: f64, unit: &'static str) -> Self {
        Self {
            lo,
            lo_open: false,
            hi,
            hi_open: false,
            unit,
        }
    }

    /// `(lo, hi)`.
    pub const fn open(lo: f64, hi: f64, unit: &'static str) -> Self {
        Self {
            lo,
            lo_open: true,
            hi,
            hi_open: true,
            unit,
        }
    }

    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64, unit: &'static str) -> Self {
        Self {
            lo,
            lo_open: true,
            hi,
            hi_open: false,
            unit,
        }
    }

    /// `[lo, hi)`.
    pub const fn below(lo: f64, hi: f64, unit: &'static str) -> Self {
        Self {
            lo,
            lo_open: false,
            hi,
            hi_open: true,
            unit,
        }
    }

    /// Whether `v` is finite and lies in the interval.
    pub fn contains(&self, v: f64) -> bool {
        let above_lo = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        let below_hi = if self.hi_open {
            v < self.hi
        } else {
            v <= self.hi
        };
        v.is_finite() && above_lo && below_hi
    }

    /// `Ok` if `v` is finite and lies in the interval.
    ///
    /// # Errors
    /// [`OutOfRange`] with `v` and these limits otherwise.
    pub fn check(self, v: f64) -> Result<(), OutOfRange> {
        if self.contains(v) {
            Ok(())
        } else {
            Err(OutOfRange {
                value: v,
                limits: self,
            })
        }
    }

    /// Writes the interval (`(0.01, 0.1] s`), each bound with `num`.
    fn write(
        &self,
        f: &mut fmt::Formatter<'_>,
        num: fn(&mut fmt::Formatter<'_>, f64) -> fmt::Result,
    ) -> fmt::Result {
        f.write_str(if self.lo_open { "(" } else { "[" })?;
        num(f, self.lo)?;
        f.write_str(", ")?;
        num(f, self.hi)?;
        f.write_str(if self.hi_open { ")" } else { "]" })?;
        self.write_unit(f)
    }

    fn write_unit(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.unit.is_empty() {
            Ok(())
        } else {
            write!(f, " {}", self.unit)
        }
    }

    /// Writes the rule a value outside these limits breaks (module docs), each bound with `num`.
    fn write_rule(
        &self,
        f: &mut fmt::Formatter<'_>,
        num: fn(&mut fmt::Formatter<'_>, f64) -> fmt::Result,
    ) -> fmt::Result {
        f.write_str("must be finite")?;
        let (lo_bounded, hi_bounded) = (self.lo.is_finite(), self.hi.is_finite());
        match (lo_bounded, hi_bounded) {
            (false, false) => Ok(()),
            (true, false) => {
                f.write_str(if self.lo_open { " and > " } else { " and >= " })?;
                num(f, self.lo)?;
                self.write_unit(f)
            }
            (false, true) => {
                f.write_str(if self.hi_open { " and < " } else { " and <= " })?;
                num(f, self.hi)?;
                self.write_unit(f)
            }
            (true, true) => {
                f.write_str(" and in ")?;
                self.write(f, num)
            }
        }
    }
}

fn display(f: &mut fmt::Formatter<'_>, v: f64) -> fmt::Result {
    write!(f, "{v}")
}

fn lower_exp(f: &mut fmt::Formatter<'_>, v: f64) -> fmt::Result {
    write!(f, "{v:e}")
}

/// `[lo, hi] unit`; with `{:e}` the bounds in exponent form (`[5e6, 5e7]`).
impl fmt::Display for Limits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(f, display)
    }
}

impl fmt::LowerExp for Limits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(f, lower_exp)
    }
}

/// A value that is not finite or lies outside its [`Limits`].
///
/// It displays as the rule the value breaks (`must be finite and in [0, 20] m`; with `{:e}` the
/// bounds in exponent form); the caller's error adds the file, the line, the field and the value
/// where it states them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfRange {
    /// The value checked.
    pub value: f64,
    /// The limits it is outside.
    pub limits: Limits,
}

impl OutOfRange {
    /// Whether the value is finite (so outside the interval) rather than NaN or an infinity.
    pub fn is_finite(&self) -> bool {
        self.value.is_finite()
    }
}

impl fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.limits.write_rule(f, display)
    }
}

impl fmt::LowerExp for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.limits.write_rule(f, lower_exp)
    }
}

impl core::error::Error for OutOfRange {}

#[cfg(test)]
mod tests {
    use std::format;
    use std::string::ToString;

    use super::*;

    const SENSOR_AGE: Limits = Limits::above(0.01, 0.1, "s");

    #[test]
    fn only_finite_values_lie_in_any_limits() {
        for limits in [
            Limits::FINITE,
            Limits::POSITIVE,
            Limits::NON_NEGATIVE,
            SENSOR_AGE,
        ] {
            for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                assert!(!limits.contains(v), "{limits} {v}");
                assert!(!limits.check(v).unwrap_err().is_finite());
            }
        }
        assert!(Limits::FINITE.contains(-1e308));
        assert!(Limits::NON_NEGATIVE.contains(0.0) && !Limits::POSITIVE.contains(0.0));
    }

    #[test]
    fn open_and_closed_ends() {
        assert!(!SENSOR_AGE.contains(0.01) && SENSOR_AGE.contains(0.1));
        assert!(Limits::below(0.0, 1.0, "").contains(0.0));
        assert!(!Limits::below(0.0, 1.0, "").contains(1.0));
        assert!(!Limits::open(0.0, 1.0, "").contains(0.0));
        assert!(Limits::closed(0.0, 1.0, "").contains(1.0));
        let e = Limits::closed(0.0, 20.0, "").check(-2.0).unwrap_err();
        assert!(e.is_finite() && e.value == -2.0);
    }

    #[test]
    fn the_rule_is_stated_one_way() {
        let rule = |limits: Limits| limits.check(f64::NAN).unwrap_err().to_string();
        assert_eq!(rule(SENSOR_AGE), "must be finite and in (0.01, 0.1] s");
        assert_eq!(rule(Limits::FINITE), "must be finite");
        assert_eq!(rule(Limits::POSITIVE), "must be finite and > 0");
        assert_eq!(rule(Limits::NON_NEGATIVE), "must be finite and >= 0");
        assert_eq!(
            rule(Limits::below(f64::NEG_INFINITY, 3.0, "m")),
            "must be finite and < 3 m"
        );
        let relief = Limits::closed(5e6, 50e6, "");
        assert_eq!(
            format!("{:e}", relief.check(1e308).unwrap_err()),
            "must be finite and in [5e6, 5e7]"
        );
        assert_eq!(format!("{SENSOR_AGE}"), "(0.01, 0.1] s");
    }
}
