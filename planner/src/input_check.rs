//! Finite-and-range checks of one step's sensor inputs, shared by Autodig and cleanup.
//!
//! Each caller keeps its own error enum; [`InputError`] tells the checks how to build it. The
//! predicate is the workspace's one finite-and-range check, [`gateway_core::range::Limits`].

use gateway_core::range::Limits;

/// Plausible pressure range (Pa): transducers may read slightly below zero; 100 MPa is far above relief.
const MIN_PRESSURE_PA: f64 = -1.0e6;
const MAX_PRESSURE_PA: f64 = 100.0e6;

/// Input names of the head-port pressures, `[boom, stick, bucket]`.
const HEAD: [&str; 3] = [
    "boom head_pressure_pa",
    "stick head_pressure_pa",
    "bucket head_pressure_pa",
];
/// Input names of the rod-port pressures, `[boom, stick, bucket]`.
const ROD: [&str; 3] = [
    "boom rod_pressure_pa",
    "stick rod_pressure_pa",
    "bucket rod_pressure_pa",
];

/// The two ways a step input can be bad, built as the caller's own error type.
pub(crate) trait InputError: Sized {
    /// The input is NaN or infinite.
    fn non_finite(input: &'static str) -> Self;
    /// The input is finite but outside `[lo, hi]`.
    fn out_of_range(input: &'static str, value: f64) -> Self;
}

/// `Ok` if `v` is finite and within `[lo, hi]`; otherwise the caller's error naming `input`.
pub(crate) fn check<E: InputError>(input: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), E> {
    Limits::closed(lo, hi, "").check(v).map_err(|e| {
        if e.is_finite() {
            E::out_of_range(input, v)
        } else {
            E::non_finite(input)
        }
    })
}

/// Checks joint `j`'s head-port then rod-port pressure against the plausible pressure range.
pub(crate) fn check_port_pressures<E: InputError>(
    j: usize,
    head_pa: f64,
    rod_pa: f64,
) -> Result<(), E> {
    check(HEAD[j], head_pa, MIN_PRESSURE_PA, MAX_PRESSURE_PA)?;
    check(ROD[j], rod_pa, MIN_PRESSURE_PA, MAX_PRESSURE_PA)
}
