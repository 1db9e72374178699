//! Where a calibrated artefact came from: the command that made it and the simulator plant version
//! its data came from (`origin` in the actuator networks' training summary, the hardness regression
//! and the grey-box nominal model; written by `excavator-ctl calibrate`, docs/models.md).

use serde::{Deserialize, Serialize};

/// The origin of a fitted artefact.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArtefactOrigin {
    /// The command that made it, with its options.
    pub made_by: String,
    /// The simulator plant version its data came from (`vcan_sim::PLANT_VERSION`); `None` for data
    /// from a real machine or of unknown origin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant_version: Option<String>,
}

impl ArtefactOrigin {
    /// An origin from `made_by` on the data of `plant_version`.
    #[must_use]
    pub fn new(made_by: impl Into<String>, plant_version: Option<&str>) -> Self {
        Self {
            made_by: made_by.into(),
            plant_version: plant_version.map(str::to_owned),
        }
    }
}
