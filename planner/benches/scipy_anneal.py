#!/usr/bin/env python3
"""The analytical soil fit of planner::estimate::fit_analytical done with SciPy, for comparison.

Same problem as the Rust fit: the modified FEE (thesis Eqs. 15-18, as in planner/src/soil.rs) with
Psi = (gamma, beta, phi, delta, c) searched in the unit box mapped onto the bounds, minimising J, the RMS
(F_x, F_z) force error (thesis 4.3.4). scipy.optimize.dual_annealing (default settings, its own local
search switched off) followed by scipy.optimize.minimize(method="Powell") with the same bounds.

Usage: scipy_anneal.py SAMPLES.csv WIDTH_M LOWER(5 comma-separated) UPPER(5 comma-separated) [SEED]
CSV columns: depth_m, slope_rad, rake_rad, swept_volume_m3, fx_n, fz_n (header line first).
Prints one JSON line: time_s, rms_n, annealing_rms_n, evaluations, params.
"""

import json
import sys
import time

import numpy as np
from scipy.optimize import dual_annealing, minimize

G = 9.81  # planner::machine::GRAVITY_M_PER_S2
EPS = 1e-6  # the denominator guard of planner::soil::fee_factors
INFEASIBLE = 1e30  # SciPy wants finite values where the Rust fit uses infinity


def main() -> None:
    path, width = sys.argv[1], float(sys.argv[2])
    lower = np.array([float(v) for v in sys.argv[3].split(",")])
    upper = np.array([float(v) for v in sys.argv[4].split(",")])
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    d, alpha, rake, vs, fx_m, fz_m = data.T
    rho_c = -rake
    cos_rake, sin_rake = np.cos(rho_c), np.sin(rho_c)
    cos_a, sin_a, tan_a = np.cos(alpha), np.sin(alpha), np.tan(alpha)
    sin_ra, cos_ra = np.sin(rake - alpha), np.cos(rake - alpha)
    evaluations = 0

    def objective(u: np.ndarray) -> float:
        nonlocal evaluations
        evaluations += 1
        density, beta, phi, delta, cohesion = lower + np.clip(u, 0.0, 1.0) * (upper - lower)
        bp = beta + phi
        if abs(np.sin(beta)) < EPS or abs(np.sin(bp)) < EPS:
            return INFEASIBLE
        cot_b, cot_bp = np.cos(beta) / np.sin(beta), np.cos(bp) / np.sin(bp)
        sd, cd = np.sin(delta), np.cos(delta)
        den = (cos_rake * cd - sin_rake * sd) + (sin_rake * cd + cos_rake * sd) * cot_bp  # Eq. 17
        if np.any(den < EPS):
            return INFEASIBLE
        slope = cos_a + sin_a * cot_bp
        wedge = np.maximum(cot_b - tan_a, 0.0)  # Eq. 15
        weight = density * G
        f = (d * d * width * weight * wedge * slope * 0.5 + cohesion * width * d * (1.0 + cot_b * cot_bp)
             + vs * weight * slope) / den  # Eq. 17
        f = np.maximum(f, 0.0)
        fx = -f * (cd * sin_ra - sd * cos_ra)  # Eq. 18, soil on bucket
        fz = -f * (cd * cos_ra + sd * sin_ra)
        j = float(np.sqrt(np.mean((fx - fx_m) ** 2 + (fz - fz_m) ** 2)))
        return j if np.isfinite(j) else INFEASIBLE

    bounds = [(0.0, 1.0)] * 5
    start = time.perf_counter()
    annealed = dual_annealing(objective, bounds, seed=seed, no_local_search=True)
    polished = minimize(objective, annealed.x, method="Powell", bounds=bounds)
    elapsed = time.perf_counter() - start
    best = polished if polished.fun <= annealed.fun else annealed
    params = lower + np.clip(best.x, 0.0, 1.0) * (upper - lower)
    print(json.dumps({
        "time_s": elapsed,
        "rms_n": float(best.fun),
        "annealing_rms_n": float(annealed.fun),
        "evaluations": evaluations,
        "params": [float(p) for p in params],
    }))


if __name__ == "__main__":
    main()
