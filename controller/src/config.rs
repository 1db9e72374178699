//! The controller's configuration: [`ControllerConfig`] (the TOML of `excavator-ctl run --config`),
//! and its loading with errors that name the file, the line and the field (the checks themselves are
//! [`crate::check`]'s).
//!
//! [`ControllerConfig`] (the TOML of `excavator-ctl run --config`) and each of its parts has a
//! `validate()` that checks every safety and timing parameter: finite, in range, consistent with the
//! others and with the protocol's timing (sensor period, gateway watchdog). The constructors
//! ([`ControllerNode::new`](crate::ControllerNode::new), [`Safety::new`](crate::Safety::new),
//! [`Estimator::new`](crate::Estimator::new), [`WorkCycle::new`](crate::WorkCycle::new)) call it, so a
//! configuration built in code cannot skip it; [`ControllerConfig::from_toml_file`] adds the file and
//! line: `plan.toml:12: safety.sensor_max_age_s = nan: must be finite and in (0.01, 0.1] s ...`.

use planner::autodig::AutodigConfig;
use planner::cleanup::CleanupConfig;
use planner::toml_lines::{field_at_offset, line_of_field, line_of_offset};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use firmware_bridge::address_claim::{CONTROLLER_NAME, GATEWAY_NAME, Name};
use firmware_bridge::name_config::NameConfig;
use firmware_bridge::secoc::{KeyFileError, SessionKey};

use crate::ControllerError;
use crate::check::{ParamError, check_count};
use crate::step::cycle::CycleConfig;
use crate::step::estimate::EstimatorConfig;
use crate::step::safety::SafetyConfig;

/// Everything the node is configured with (besides the machine and the Autodig maps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Safety layer.
    pub safety: SafetyConfig,
    /// Estimator.
    pub estimator: EstimatorConfig,
    /// Work cycle and plan.
    pub cycle: CycleConfig,
    /// Autodig parameters. The relief pressures and the bucket capacity are taken from the machine
    /// file at construction; the perception flags are set per dig.
    pub autodig: AutodigConfig,
    /// Cleanup parameters (relief pressures from the machine file).
    pub cleanup: CleanupConfig,
    /// Send the track valve commands (and the `ControllerStatus`) every this many steps (5: 20 Hz at
    /// 100 Hz), 1 to [`MAX_TRACK_EVERY_STEPS`]. Default 5.
    pub track_every_steps: u32,
    /// Start the work cycle at the first step (otherwise call [`ControllerNode::start`](crate::ControllerNode::start)). Default true.
    pub autostart: bool,
    /// Authentication of the control path.
    pub security: SecurityConfig,
    /// The J1939 NAMEs of the controller and of the gateway it expects.
    pub j1939: J1939Config,
}

/// The `[j1939]` table: the controller's NAME (`[j1939.name]`) and the NAME the gateway at `0x80`
/// must claim with (`[j1939.gateway_name]`), each a full [`NameConfig`] table (every field given,
/// each within its width). A claim for `0x27` or `0x80` from any other NAME is an intrusion
/// (`Fault::AddressIntrusion`). Defaults: the project's NAMEs
/// ([`firmware_bridge::address_claim::CONTROLLER_NAME`], [`GATEWAY_NAME`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct J1939Config {
    /// The controller's NAME.
    pub name: NameConfig,
    /// The gateway's NAME.
    pub gateway_name: NameConfig,
}

impl Default for J1939Config {
    fn default() -> Self {
        Self {
            name: NameConfig::from(CONTROLLER_NAME),
            gateway_name: NameConfig::from(GATEWAY_NAME),
        }
    }
}

impl J1939Config {
    /// The two NAMEs, `(controller, gateway)`: each field within its width, not arbitrary-address
    /// capable, and different from each other (a NAME is unique on a J1939 network).
    ///
    /// # Errors
    /// [`ParamError`] naming the field (`j1939.name.identity_number`).
    pub fn names(&self) -> Result<(Name, Name), ParamError> {
        let one = |key: &str, config: &NameConfig| {
            config.name().map_err(|e| {
                ParamError::new(
                    "j1939",
                    format!("{key}.{}", e.field),
                    Some(e.value.to_string()),
                    e.rule.to_string(),
                )
            })
        };
        let controller = one("name", &self.name)?;
        let gateway = one("gateway_name", &self.gateway_name)?;
        if controller == gateway {
            return Err(ParamError::new(
                "j1939",
                "gateway_name",
                None,
                "must differ from j1939.name (a NAME is unique on the network)",
            ));
        }
        Ok((controller, gateway))
    }
}

/// The `[security]` table: the machine's authentication key (docs/protocol.md, "Freshness and
/// authentication").
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SecurityConfig {
    /// File with the machine's 128-bit key: 32 hex digits, readable by its owner only (`chmod
    /// 600`); the gateway holds the same key (`excavator-sim --key-file`). A relative path is taken
    /// from the config file's folder; `excavator-ctl run --key-file` overrides it. Default: none,
    /// and then `run` refuses to arm unless `insecure_no_key` is set (or it only listens).
    pub key_file: Option<PathBuf>,
    /// Run on the bus without a key: the control frames are sealed with the public all-zero key
    /// ([`SessionKey::PUBLIC`]), which anyone who reads docs/protocol.md can forge. For a bench test
    /// only; logged as an error at every start. Default false: no key, no motion.
    pub insecure_no_key: bool,
}

impl SecurityConfig {
    /// `key_file`, when set, names a file (not an empty path).
    ///
    /// # Errors
    /// [`ParamError`] for an empty path.
    pub fn validate(&self) -> Result<(), ParamError> {
        match &self.key_file {
            Some(p) if p.as_os_str().is_empty() => Err(ParamError::new(
                "security",
                "key_file",
                Some("\"\"".to_owned()),
                "must name the key file (or be left out: no key)",
            )),
            _ => Ok(()),
        }
    }

    /// Reads and checks the key of `key_file` ([`SessionKey::from_file`]); `None` without one.
    ///
    /// # Errors
    /// [`KeyFileError`] naming the file and what is wrong with it.
    pub fn load_key(&self) -> Result<Option<SessionKey>, KeyFileError> {
        self.key_file
            .as_deref()
            .map(SessionKey::from_file)
            .transpose()
    }

    /// The key to seal with when the controller transmits: the provisioned one, or
    /// [`SessionKey::PUBLIC`] when `insecure_no_key` asks for it explicitly; `listen_only` needs
    /// none (it never transmits).
    ///
    /// # Errors
    /// [`MissingKey`] when there is no key, no explicit insecure mode and the controller transmits.
    pub fn key_for_motion(
        key: Option<SessionKey>,
        insecure_no_key: bool,
        listen_only: bool,
    ) -> Result<KeyUse, MissingKey> {
        match key {
            Some(key) => Ok(KeyUse::Provisioned(key)),
            None if listen_only => Ok(KeyUse::ListenOnly),
            None if insecure_no_key => Ok(KeyUse::Insecure),
            None => Err(MissingKey),
        }
    }
}

/// How the control frames are keyed ([`SecurityConfig::key_for_motion`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KeyUse {
    /// The machine's provisioned key.
    Provisioned(SessionKey),
    /// No key and nothing sent: listen-only.
    ListenOnly,
    /// No key, asked for explicitly: sealed with the public key, forgeable by anyone on the bus.
    Insecure,
}

/// No key provisioned and no explicit insecure mode: the controller does not arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "no key provisioned: refusing to arm. Provision the machine's key at both ends (32 random hex \
     digits, mode 600: the gateway's, and --key-file or [security] key_file here; see \
     docs/deployment.md, \"The machine's key\"), or run --listen-only. For a bench test only, \
     --insecure-no-key (security.insecure_no_key = true) runs with the public all-zero key"
)]
pub struct MissingKey;

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            safety: SafetyConfig::default(),
            estimator: EstimatorConfig::default(),
            cycle: CycleConfig::default(),
            autodig: AutodigConfig::default(),
            // The gateway's position loop lags a lowering setpoint by several centimetres; a slower
            // probe and a larger lag threshold keep that lag from passing for floor contact. The
            // planner starts a cleanup above what is left of the bench (up to about 2.5 m over the
            // floor on the default bench), so the probe may need to go that far down.
            cleanup: CleanupConfig {
                descent_speed_m_per_s: 0.05,
                probe_lag_m: 0.15,
                probe_max_depth_m: 3.0,
                ..CleanupConfig::default()
            },
            track_every_steps: 5,
            autostart: true,
            security: SecurityConfig::default(),
            j1939: J1939Config::default(),
        }
    }
}

/// Most control steps between two track valve commands (and `ControllerStatus` messages): 50 ms at
/// the 10 ms control period, half the gateway's 100 ms command timeout, so a moving track is never
/// stopped by a stale command.
pub const MAX_TRACK_EVERY_STEPS: u32 = 5;

impl ControllerConfig {
    /// Checks every part ([`SafetyConfig::validate`], [`EstimatorConfig::validate`],
    /// [`CycleConfig::validate`], the Autodig and cleanup parameters) and `track_every_steps`.
    ///
    /// # Errors
    /// The first [`ParamError`], naming the field as the TOML file spells it.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.safety.validate()?;
        self.security.validate()?;
        self.j1939.names()?;
        self.estimator.validate()?;
        self.cycle.validate()?;
        self.autodig.validate().map_err(|e| match e {
            planner::autodig::AutodigError::InvalidConfig { field, reason } => {
                ParamError::new("autodig", field, None, reason)
            }
            other => ParamError::new("autodig", "", None, other.to_string()),
        })?;
        self.cleanup.validate().map_err(|e| match e {
            planner::cleanup::CleanupError::InvalidConfig { field, reason } => {
                ParamError::new("cleanup", field, None, reason)
            }
            other => ParamError::new("cleanup", "", None, other.to_string()),
        })?;
        check_count(
            "",
            "track_every_steps",
            u64::from(self.track_every_steps),
            1,
            u64::from(MAX_TRACK_EVERY_STEPS),
            "track commands at least every 50 ms, half the gateway's 100 ms command timeout",
        )
    }

    /// Parses and checks a TOML file's text; missing fields take their defaults.
    ///
    /// # Errors
    /// [`ControllerError::Config`] naming the line and the field; [`Self::from_toml_file`] names the
    /// file too.
    pub fn from_toml_str(text: &str) -> Result<Self, ControllerError> {
        Self::from_toml_str_named(text, "").map_err(|e| ControllerError::Config {
            field: "controller config",
            reason: e.to_string(),
        })
    }

    /// Reads, parses and checks a controller config file (`excavator-ctl run --config`); a relative
    /// `security.key_file` is taken from the file's folder.
    ///
    /// # Errors
    /// [`ConfigFileError`] naming the file, the line and the field.
    pub fn from_toml_file(path: &Path) -> Result<Self, ConfigFileError> {
        let origin = path.display().to_string();
        // A regular file of bounded size (`/dev/zero` or a FIFO as `--config` is refused at once).
        let text = planner::config_file::read_text(path).map_err(|reason| ConfigFileError::Io {
            origin: origin.clone(),
            source: std::io::Error::other(reason),
        })?;
        let mut config = Self::from_toml_str_named(&text, &origin)?;
        if let (Some(key), Some(dir)) = (&config.security.key_file, path.parent())
            && key.is_relative()
        {
            config.security.key_file = Some(dir.join(key));
        }
        Ok(config)
    }

    /// Parses and checks TOML text, naming `origin` (a file name; empty: none) in errors.
    ///
    /// # Errors
    /// [`ConfigFileError::Parse`] for bad TOML or a value of the wrong type,
    /// [`ConfigFileError::Invalid`] for a value out of range or inconsistent.
    pub fn from_toml_str_named(text: &str, origin: &str) -> Result<Self, ConfigFileError> {
        let config: Self = toml::from_str(text).map_err(|e| {
            let offset = e.span().map(|s| s.start);
            let mut message = e.message().trim().to_owned();
            if let Some(field) = offset.and_then(|o| field_at_offset(text, o))
                && !message.contains(&field)
            {
                message = format!("{field}: {message}");
            }
            ConfigFileError::Parse {
                origin: origin.to_owned(),
                line: offset.map(|o| line_of_offset(text, o)),
                message,
            }
        })?;
        config
            .validate()
            .map_err(|error| ConfigFileError::Invalid {
                origin: origin.to_owned(),
                line: line_of_field(text, &error.path()),
                error: Box::new(error),
            })?;
        Ok(config)
    }
}

/// A controller config file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    /// The file cannot be read.
    #[error("{origin}: cannot read: {source}")]
    Io {
        /// The file name.
        origin: String,
        /// The error.
        source: std::io::Error,
    },
    /// Not TOML, an unknown key, or a value of the wrong type (the message names the field).
    #[error("{}: {message}", place(origin, *line))]
    Parse {
        /// The file name (empty: none).
        origin: String,
        /// 1-based line, when known.
        line: Option<usize>,
        /// The parser's message.
        message: String,
    },
    /// A value out of range or inconsistent.
    #[error("{}: {error}", place(origin, *line))]
    Invalid {
        /// The file name (empty: none).
        origin: String,
        /// 1-based line of the field (or of its table when the value is a default), when known.
        line: Option<usize>,
        /// The field and what is wrong with it (boxed: errors are rare, results common).
        error: Box<ParamError>,
    },
}

fn place(origin: &str, line: Option<usize>) -> String {
    match (origin.is_empty(), line) {
        (false, Some(l)) => format!("{origin}:{l}"),
        (false, None) => origin.to_owned(),
        (true, Some(l)) => format!("line {l}"),
        (true, None) => "controller config".to_owned(),
    }
}
