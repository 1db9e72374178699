//! The trials of the forward selection: an effect of the library or a machine parameter, with its
//! range, scale, starting value and how a fitted change is applied and reported.

use crate::effects::{Candidate, CandidateEffect as _};
use crate::greybox::{Augmentation, GreyBoxParams, SignalGroups};
use crate::parameters::{FACTOR_RANGE, ParameterLibrary, factor_range};

/// A candidate of the forward selection: an effect of the library, or a machine parameter (index
/// into [`super::AnalysisConfig::parameters`]) fitted as a factor on the file's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Trial {
    Effect(Candidate),
    Parameter(usize),
}

impl Trial {
    pub(super) fn groups(self, library: Option<&ParameterLibrary>) -> SignalGroups {
        match (self, library) {
            (Trial::Effect(c), _) => c.groups(),
            (Trial::Parameter(i), Some(l)) => ParameterLibrary::groups_of(&l.parameters[i].key),
            (Trial::Parameter(_), None) => SignalGroups::default(),
        }
    }

    pub(super) fn range(self, library: Option<&ParameterLibrary>) -> (f64, f64) {
        match (self, library) {
            (Trial::Effect(c), _) => c.range(),
            (Trial::Parameter(i), Some(l)) => factor_range(&l.parameters[i].key),
            (Trial::Parameter(_), None) => FACTOR_RANGE,
        }
    }

    pub(super) fn scale(self) -> f64 {
        match self {
            Trial::Effect(c) => c.scale(),
            Trial::Parameter(_) => 1.0,
        }
    }

    /// The value of the starting model (an effect's calibrated magnitude; a factor of 1).
    pub(super) fn base(self, base: &Augmentation) -> f64 {
        match self {
            Trial::Effect(c) => base.get(c),
            Trial::Parameter(_) => 1.0,
        }
    }

    /// The model with the trial at `x` on top of `aug` and `params`: an effect's magnitude, or a
    /// parameter's factor on the file's value (`None`: the machine file is not valid there). The
    /// parameters are `None` when the trial leaves them as they are.
    pub(super) fn at(
        self,
        x: f64,
        aug: &Augmentation,
        params: &GreyBoxParams,
        library: Option<&ParameterLibrary>,
    ) -> Option<(Augmentation, Option<GreyBoxParams>)> {
        match (self, library) {
            (Trial::Effect(e), _) => {
                let mut a = *aug;
                a.set(e, x);
                Some((a, None))
            }
            (Trial::Parameter(i), Some(l)) => l.apply(params, i, x).ok().map(|p| (*aug, Some(p))),
            (Trial::Parameter(_), None) => None,
        }
    }

    /// The model with `self` at `x` and `other` at `y` on top of `aug` and `params`.
    pub(super) fn at_pair(
        self,
        other: Trial,
        (x, y): (f64, f64),
        aug: &Augmentation,
        params: &GreyBoxParams,
        library: Option<&ParameterLibrary>,
    ) -> Option<(Augmentation, Option<GreyBoxParams>)> {
        let (a, p) = self.at(x, aug, params, library)?;
        let (a, q) = other.at(y, &a, p.as_ref().unwrap_or(params), library)?;
        Some((a, q.or(p)))
    }

    /// How a fitted change of this trial is reported: `(kind, value, uncertainty, unit)`; a
    /// parameter's value is the fitted value in the machine file's units.
    pub(super) fn reported(
        self,
        change: f64,
        uncertainty: f64,
        library: Option<&ParameterLibrary>,
    ) -> (&'static str, f64, f64, &'static str) {
        match (self, library) {
            (Trial::Parameter(i), Some(l)) => {
                let p = &l.parameters[i];
                (
                    "parameter",
                    p.nominal * (1.0 + change),
                    p.nominal.abs() * uncertainty,
                    p.unit,
                )
            }
            (Trial::Effect(e), _) => ("effect", change, uncertainty, e.unit()),
            (Trial::Parameter(_), None) => ("parameter", change, uncertainty, "1"),
        }
    }

    pub(super) fn name(self, library: Option<&ParameterLibrary>) -> String {
        match (self, library) {
            (Trial::Effect(c), _) => c.name().to_string(),
            (Trial::Parameter(i), Some(l)) => l.parameters[i].key.clone(),
            (Trial::Parameter(i), None) => format!("parameter {i}"),
        }
    }
}
