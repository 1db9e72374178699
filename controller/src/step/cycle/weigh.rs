//! Weigh: the payload estimate averaged over whole periods of the implement's oscillation, and the
//! thresholds of the weighing phase.

/// Weigh: deviations of the payload estimate from its running mean smaller than this do not count as a
/// side change of the implement's oscillation (noise), N.
pub(super) const WEIGH_DEADBAND_N: f64 = 1_000.0;
/// Weigh: how long past `weigh_settle_s + weigh_window_s` to wait for the end of a whole oscillation
/// period before falling back to the plain mean, s (two periods of the default machine's 2 Hz).
pub(super) const WEIGH_MAX_EXTRA_S: f64 = 1.0;
/// Weigh: a payload estimate below minus this is not a payload but a bucket the ground carries (a dig
/// or cleanup that ended with the bucket resting on the soil: the boom cylinder then holds less than
/// the empty implement's weight, seen as -2500 to -4800 kg in 100-dig sessions), kg. The boom lifts
/// [`WEIGH_LIFT_RAD`] and the weighing starts over, at most [`WEIGH_MAX_LIFTS`] times; after that the
/// weight is reported unknown.
pub(super) const WEIGH_SUPPORTED_KG: f64 = 300.0;
/// Weigh: the boom lift that takes a supported bucket off the ground, rad (about 8.6 deg: 0.5-0.8 m
/// at the tip on the default machine).
pub(super) const WEIGH_LIFT_RAD: f64 = 0.15;
/// Weigh: lifts before the weight is reported unknown.
pub(super) const WEIGH_MAX_LIFTS: u32 = 2;
/// Weigh: a lift that takes longer ends anyway (a boom against its stop or stalled), s.
pub(super) const WEIGH_LIFT_MAX_S: f64 = 3.0;

/// The payload estimate averaged over whole periods of the implement's oscillation (Weigh).
///
/// After the valves close the implement keeps swinging on its oil columns (about 2 Hz on the default
/// machine) and the static estimate with it, by +-10 kN after a dig and up to +-35 kN after a cleanup
/// (measured in the simulator). A window that is not a whole number of periods reads part of a swing:
/// with the HIL plan's 0.2 s window (`tests/src/plan.rs`) the same full bucket (25 kN) read -5..63 kN.
/// So the mean is taken from the first time the estimate crosses its running mean to a crossing an
/// even number of crossings later (whole periods), the first one after the configured window; a steady
/// estimate (never outside the deadband) is averaged over the window as before.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct WeighAverage {
    /// Every sample since the settle time (the reference level for the crossings), N.
    all_sum_n: f64,
    all_samples: u32,
    /// Samples from the first crossing on, N.
    sum_n: f64,
    samples: u32,
    /// The same up to (without) the latest whole-period boundary, N.
    whole_sum_n: f64,
    whole_samples: u32,
    /// Side of the reference of the last sample outside the deadband.
    above: Option<bool>,
    crossings: u32,
}

impl WeighAverage {
    /// Adds a sample; returns whether it starts a new whole period (it is then not yet in the mean).
    pub(super) fn push(&mut self, weight_n: f64) -> bool {
        self.all_sum_n += weight_n;
        self.all_samples += 1;
        let reference = self.all_sum_n / f64::from(self.all_samples);
        let deviation = weight_n - reference;
        let mut crossed = false;
        if deviation.abs() > WEIGH_DEADBAND_N {
            let above = deviation > 0.0;
            if self.above.is_some_and(|a| a != above) {
                self.crossings += 1;
                crossed = true;
            }
            self.above = Some(above);
        }
        let boundary = crossed && self.crossings >= 3 && self.crossings % 2 == 1;
        if boundary {
            self.whole_sum_n = self.sum_n;
            self.whole_samples = self.samples;
        }
        if self.crossings >= 1 {
            self.sum_n += weight_n;
            self.samples += 1;
        }
        boundary
    }

    /// No sample has left the deadband around the running mean.
    pub(super) fn steady(&self) -> bool {
        self.above.is_none()
    }

    /// The mean over whole periods if `at_boundary`, else over every sample.
    pub(super) fn mean_n(&self, at_boundary: bool) -> Option<f64> {
        if at_boundary && self.whole_samples > 0 {
            Some(self.whole_sum_n / f64::from(self.whole_samples))
        } else if self.all_samples > 0 {
            Some(self.all_sum_n / f64::from(self.all_samples))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (HIL cleanup): a 0.2 s window read the oscillating estimate of a full bucket
    /// (25 kN) at -5..63 kN; the mean over whole periods does not depend on where the window falls.
    #[test]
    fn weighing_averages_whole_periods_of_the_oscillation() {
        let (true_n, amp_n, hz) = (25_000.0, 30_000.0, 2.0);
        for phase in [0.0, 0.7, 1.9, 3.0, 4.4, 5.5] {
            let mut a = WeighAverage::default();
            let mut short = (0.0, 0);
            let mut t = 0.0_f64;
            let mean = loop {
                let w = true_n
                    + amp_n
                        * (-0.3 * t).exp()
                        * (2.0 * std::f64::consts::PI * hz * t + phase).sin();
                let boundary = a.push(w);
                if t < 0.2 {
                    short = (short.0 + w, short.1 + 1);
                }
                if t >= 0.2 && boundary {
                    break a.mean_n(true).unwrap();
                }
                t += 0.01;
                assert!(t < 2.0, "no whole period found");
            };
            assert!(
                (mean - true_n).abs() < 0.1 * true_n,
                "phase {phase}: {mean}"
            );
            // Ends within about one period after the window.
            assert!(t < 0.2 + 0.5 + 0.3, "phase {phase}: {t}");
            let short_mean = short.0 / f64::from(short.1);
            if phase == 0.7 {
                assert!((short_mean - true_n).abs() > 0.3 * true_n, "{short_mean}");
            }
        }
        // A steady estimate is averaged over the window.
        let mut a = WeighAverage::default();
        for _ in 0..20 {
            assert!(!a.push(20_000.0));
        }
        assert!(a.steady());
        assert_eq!(a.mean_n(false), Some(20_000.0));
    }
}
