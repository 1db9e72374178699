//! The thesis's figures and statements that the reproductions are compared with, and how a
//! comparison reads ("as in the thesis" / "differs from the thesis"): Table 1 (3.2), Table 2 (4.4) and
//! Fig. 52 (5.2). The simulator's (`experiment`) and the dig model's (`model`) reproductions both
//! check against these.

use serde::Serialize;

/// The thesis's Table 1: initial stick angle (deg), plain Autodig time (s) and payload (lb), with the
/// perception enhancements time (s) and payload (lb).
pub const THESIS_TABLE1: [(f64, f64, f64, f64, f64); 3] = [
    (-87.0, 6.58, 4145.0, 7.13, 5331.0),
    (-70.0, 10.35, 5172.0, 7.47, 5329.0),
    (-50.0, 13.83, 6526.0, 8.77, 5338.0),
];

/// Pounds to kilograms (the thesis gives Table 1's payloads in lb).
pub const LB_TO_KG: f64 = 0.453_592;

/// The thesis's Table 2: force factor, time (s), volume (m^3), energy (kJ).
pub const THESIS_TABLE2: [(f64, f64, f64, f64); 3] = [
    (1.0, 5.5, 2.2, 113.0),
    (2.0, 8.1, 2.5, 234.0),
    (3.0, 7.8, 2.1, 253.0),
];

/// A bucket counts as full from this share of its capacity.
pub const FULL_FILL: f64 = 0.85;
/// "About half" full: this range of the capacity.
pub const HALF_FILL: (f64, f64) = (0.35, 0.65);
/// The thesis's soft-soil cost of the higher index: time, energy (fractions).
pub const THESIS_SOFT_COST: (f64, f64) = (0.60, 0.75);

/// The thesis's statements about Fig. 52, checked on a soft and a hard soil's pair of digs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Fig52Checks {
    /// Soft soil: both indices fill the bucket (at least [`FULL_FILL`]).
    pub soft_both_full: bool,
    /// Soft soil: the higher index takes more time and more energy.
    pub soft_high_index_costs: bool,
    /// Hard soil: the lower index fills the bucket about half ([`HALF_FILL`]).
    pub hard_low_index_half: bool,
    /// Hard soil: the higher index fills the bucket (at least [`FULL_FILL`]).
    pub hard_high_index_full: bool,
}

impl Fig52Checks {
    /// The checks on `(fill, time s, energy kJ)` of index 1 and index 5 in the soft and in the hard
    /// soil (fill: the share of the bucket's capacity).
    #[must_use]
    pub fn from_figures(soft: [(f64, f64, f64); 2], hard: [(f64, f64, f64); 2]) -> Self {
        Self {
            soft_both_full: soft.iter().all(|d| d.0 >= FULL_FILL),
            soft_high_index_costs: soft[1].1 > soft[0].1 && soft[1].2 > soft[0].2,
            hard_low_index_half: (HALF_FILL.0..=HALF_FILL.1).contains(&hard[0].0),
            hard_high_index_full: hard[1].0 >= FULL_FILL,
        }
    }

    /// Each statement, worded, and whether it holds.
    #[must_use]
    pub fn statements(&self) -> [(String, bool); 4] {
        [
            (
                format!("soft soil, both indices fill (>= {})", pct(FULL_FILL)),
                self.soft_both_full,
            ),
            (
                "soft soil, index 5 costs time and energy".to_owned(),
                self.soft_high_index_costs,
            ),
            (
                format!(
                    "hard soil, index 1 fills about half ({}-{})",
                    pct(HALF_FILL.0),
                    pct(HALF_FILL.1)
                ),
                self.hard_low_index_half,
            ),
            (
                format!("hard soil, index 5 fills (>= {})", pct(FULL_FILL)),
                self.hard_high_index_full,
            ),
        ]
    }

    /// All four hold.
    #[must_use]
    pub fn all(&self) -> bool {
        self.soft_both_full
            && self.soft_high_index_costs
            && self.hard_low_index_half
            && self.hard_high_index_full
    }
}

/// The thesis's statements about Table 2 (4.4) on `(time s, swept volume m^3, energy kJ)` at force
/// factor 1, 2 and 3: each statement and whether it holds.
#[must_use]
pub fn table2_checks(r: [(f64, f64, f64); 3]) -> [(&'static str, bool); 5] {
    [
        ("time rises 1 -> 2", r[1].0 > r[0].0),
        ("time falls 2 -> 3", r[2].0 < r[1].0),
        ("volume rises 1 -> 2", r[1].1 > r[0].1),
        ("volume falls 2 -> 3", r[2].1 < r[1].1),
        (
            "energy rises throughout",
            r[1].2 > r[0].2 && r[2].2 > r[1].2,
        ),
    ]
}

/// How a reproduction's check reads: "as in the thesis" or "differs from the thesis".
#[must_use]
pub fn thesis_verdict(ok: bool) -> &'static str {
    if ok {
        "as in the thesis"
    } else {
        "differs from the thesis"
    }
}

/// Appends a blank line, then a line per statement: whether it holds as in the thesis.
pub fn write_checks<S: std::fmt::Display>(
    s: &mut String,
    checks: impl IntoIterator<Item = (S, bool)>,
) {
    use std::fmt::Write as _;
    // Writing into a String cannot fail.
    let _ = writeln!(s);
    for (statement, ok) in checks {
        let _ = writeln!(s, "  {statement}: {}", thesis_verdict(ok));
    }
}

/// `x` as a whole percentage, e.g. "85 %".
#[must_use]
pub fn pct(x: f64) -> String {
    format!("{:.0} %", 100.0 * x)
}
