//! One-dimensional minimisation: Brent's method (parabolic steps through the three best points,
//! golden-section steps where they fall badly; after Brent 1973 and Press et al.), used by the soil
//! estimator's line searches ([`crate::estimate`]) and by the discrepancy workflow's fit of a
//! candidate's magnitude.

/// Brent's minimisation of `f` in the bracket `[a, b]` from the best point so far `(x, f(x))` and two
/// others known (the same point three times when only one is known), at most `iterations`
/// evaluations, until the best point is within `tol` of both ends of the bracket. Returns the best
/// point and its value `(x, f(x))`.
///
/// A parabolic step must be shorter than half the step before it and land inside the bracket, and it
/// is never closer to the best point than half the tolerance (a step onto it tells nothing; one beside
/// it, into the larger side, narrows the bracket to the tolerance); otherwise the step is a golden
/// section of the larger side.
pub fn brent(
    f: &mut impl FnMut(f64) -> f64,
    (mut a, mut b): (f64, f64),
    [(mut x, mut fx), (mut w, mut fw), (mut v, mut fv)]: [(f64, f64); 3],
    tol: f64,
    iterations: usize,
) -> (f64, f64) {
    const GOLDEN: f64 = 0.381_966_011_250_105_1;
    // `x` the best point so far, `w` and `v` the second and third (Brent's names); a parabolic
    // step must be shorter than half the step before last.
    let mut last_step = b - a;
    for _ in 0..iterations {
        if x - a <= tol && b - x <= tol {
            break;
        }
        let mid = 0.5 * (a + b);
        // Towards the larger side of the bracket.
        let outward = if x >= mid { -1.0 } else { 1.0 };
        let mut u = f64::NAN;
        if w != x && v != x && v != w {
            // Vertex of the parabola through x, w and v.
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let p = (x - v) * q - (x - w) * r;
            let q2 = 2.0 * (q - r);
            if q2 != 0.0 {
                let mut d = -p / q2;
                if d.abs() < 0.5 * last_step.abs() && x + d > a && x + d < b {
                    // Never closer to the best point than half the tolerance: a step onto it
                    // tells nothing; one beside it, into the larger side, narrows the bracket
                    // to the tolerance.
                    if d.abs() < 0.5 * tol {
                        d = 0.5 * tol * outward;
                    }
                    if x + d > a && x + d < b {
                        u = x + d;
                        last_step = d;
                    }
                }
            }
        }
        if u.is_nan() {
            last_step = if outward < 0.0 { a - x } else { b - x };
            u = x + GOLDEN * last_step;
        }
        let fu = f(u);
        if fu <= fx {
            if u >= x {
                a = x;
            } else {
                b = x;
            }
            (v, fv) = (w, fw);
            (w, fw) = (x, fx);
            (x, fx) = (u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv) = (w, fw);
                (w, fw) = (u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parabola with its minimum inside the bracket, started at one end.
    const VERTEX: f64 = 0.37;

    #[test]
    fn brent_finds_the_vertex_of_a_parabola_from_one_known_point() {
        let f = |x: f64| (x - VERTEX).powi(2) + 1.0;
        let start = (0.0, f(0.0));
        let mut calls = 0;
        let (x, v) = brent(
            &mut |x| {
                calls += 1;
                f(x)
            },
            (-1.0, 1.0),
            [start; 3],
            1e-6,
            60,
        );
        assert!((x - VERTEX).abs() < 1e-5, "{x}");
        assert!((v - 1.0).abs() < 1e-9, "{v}");
        assert!(
            calls < 60,
            "{calls} evaluations: it should stop on the tolerance"
        );
    }

    #[test]
    fn brent_stays_inside_the_bracket_when_the_minimum_is_outside() {
        let (x, _) = brent(
            &mut |x: f64| (x - 3.0).powi(2),
            (0.0, 1.0),
            [(0.5, 6.25); 3],
            1e-6,
            80,
        );
        assert!((0.0..=1.0).contains(&x), "{x}");
        assert!(x > 1.0 - 1e-5, "{x}");
    }
}
