//! The search for a candidate's magnitude: a coarse grid over its range, then Brent's method
//! ([`planner::optimize::brent`]) around the best grid point.

use planner::optimize::brent;

/// The search stops when the bracket around the minimum is narrower than this share of the range.
pub(super) const SEARCH_TOLERANCE: f64 = 2e-4;

/// Minimisation of `f` on `[lo, hi]`: a coarse grid first (the cost curves of the timing effects
/// are not unimodal over the whole range), then Brent's method in the grid cell around the best
/// point: a step to the vertex of the parabola through the bracket and the best point where it
/// falls well inside the bracket, a golden-section step into the larger half where it does not;
/// at most `iterations` steps, until the bracket is narrower than [`SEARCH_TOLERANCE`] of the
/// range. The cost near a candidate's fit is close to a parabola (a chi-square), so a few steps
/// do; a best grid point at a bound (a candidate that is absent) takes one evaluation beside it
/// to see the cost rise into the range.
pub(super) fn minimise(
    mut f: impl FnMut(f64) -> f64,
    lo: f64,
    hi: f64,
    grid: usize,
    iterations: usize,
) -> (f64, f64) {
    let grid = grid.max(3);
    let step = (hi - lo) / (grid - 1) as f64;
    let tol = SEARCH_TOLERANCE * (hi - lo);
    let points: Vec<(f64, f64)> = (0..grid)
        .map(|g| {
            let x = if g + 1 == grid {
                hi
            } else {
                lo + step * g as f64
            };
            (x, f(x))
        })
        .collect();
    let i = (0..grid)
        .min_by(|a, b| points[*a].1.total_cmp(&points[*b].1))
        .unwrap_or(0);
    // Zero (no change) is always tried; it is a grid point when it is an end of the range.
    let zero = 0.0_f64.clamp(lo, hi);
    let mut best = points[i];
    if zero != lo && zero != hi && points.iter().all(|(x, _)| *x != zero) {
        let v = f(zero);
        if v < best.1 {
            best = (zero, v);
        }
    }
    if best.0 != points[i].0 {
        // Zero beat the grid: search its neighbourhood, from it alone.
        return brent(
            &mut f,
            ((zero - step).max(lo), (zero + step).min(hi)),
            [best; 3],
            tol,
            iterations,
        );
    }
    let (mut a, mut b) = (points[i.saturating_sub(1)], points[(i + 1).min(grid - 1)]);
    if i == 0 || i + 1 == grid {
        // At a bound: the minimum is there unless the cost falls just inside.
        let inside = if i == 0 { best.0 + tol } else { best.0 - tol };
        let v = f(inside);
        if v >= best.1 {
            return best;
        }
        if i == 0 {
            a = best;
        } else {
            b = best;
        }
        best = (inside, v);
    }
    // The bracket's ends are the other two points of the first parabola.
    brent(&mut f, (a.0, b.0), [best, a, b], tol, iterations)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_search_finds_a_parabola_minimum_inside_bounds_in_few_evaluations() {
        let mut calls = 0;
        let (x, v) = minimise(
            |x| {
                calls += 1;
                (x - 0.37).powi(2) + 1.0
            },
            0.0,
            1.0,
            9,
            30,
        );
        assert!((x - 0.37).abs() < 1e-4, "{x}");
        assert!((v - 1.0).abs() < 1e-8);
        // The grid and a few parabolic steps.
        assert!(calls <= 9 + 6, "{calls} evaluations");
        // A cost rising from the lower bound: the grid and one evaluation beside the bound.
        let mut calls = 0;
        let (x, _) = minimise(
            |x| {
                calls += 1;
                (x + 0.1).powi(2)
            },
            0.0,
            1.0,
            9,
            30,
        );
        assert_eq!((x, calls), (0.0, 10));
        // Not unimodal: the grid finds the deeper well.
        let (x, _) = minimise(
            |x: f64| (x - 0.8).powi(2).min(0.05 + (x - 0.2).powi(2)),
            0.0,
            1.0,
            9,
            30,
        );
        assert!((x - 0.8).abs() < 1e-3, "{x}");
        let (x, _) = minimise(|x| (x + 5.0).powi(2), -1.0, 1.0, 9, 30);
        assert!((x + 1.0).abs() < 1e-9, "clamped at the bound: {x}");
    }
}
