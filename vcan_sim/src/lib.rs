//! `vcan_sim`: the excavator emulated behind its CAN gateway (`excavator-sim`).
//!
//! # Layout
//!
//! Physics is pure (no I/O, no clocks):
//! - [`hydraulics`]: pumps, open-centre valves, relief valves, chambers and cylinders (Eqs. 1-3).
//! - [`linkage`]: cylinder extension <-> joint angle, loads and inertia on each cylinder (Appendix).
//! - [`soil_contact`]: the true terrain and soil, cutting, bucket fill, spill and dump, FEE forces
//!   (Eqs. 14-18).
//! - [`sensors`]: resolvers, pressures, odometry and the range-sensor emulation (ray casting).
//! - [`plant`]: the whole machine stepped at 1 kHz.
//! - [`effects`]: the hidden effects the plant applies (the catalogue [`planner::effects`]);
//!   [`scenario`]: bench scenarios (`config/bench.toml`).
//! - [`node`]: the gateway firmware ([`firmware_bridge::gateway`]) in front of the plant: frames in,
//!   frames out, still without I/O; its sensor frames ([`node::sensor_messages`]) are the ones every
//!   trace of the simulated gateway holds.
//!
//! I/O lives only in [`embedded`] (in-process bus, virtual time), [`realtime`] (SocketCAN, tokio,
//! scan socket) and the binary.
//!
//! # Data flow
//!
//! ```text
//! controller frames -> Gateway::on_frame -> Gateway::tick -> valve commands -> Plant::step (1 kHz)
//!   -> sensors -> JointAngles, JointRates, AuxValveMeasured, PumpPressures, GatewayStatus, ...
//! scan requests (socket or function call) -> Plant::scan -> world points
//! ```

use std::path::Path;

use firmware_bridge::address_claim::{GATEWAY_NAME, Name};
use firmware_bridge::name_config::NameConfig;
use planner::machine::{ConfigError, MachineConfig};

pub mod effects;
pub mod embedded;
pub mod hydraulics;
pub mod linkage;
pub mod node;
pub mod plant;
pub mod realtime;
pub mod scenario;
pub mod sensors;
pub mod soil_contact;

use effects::{EffectError, EffectSet};
use plant::{Plant, PlantError};
use scenario::{Scenario, ScenarioError};

/// The version of the default plant: what every artefact fitted on the simulator (the actuator
/// networks, the hardness regression, the discrepancy workflow's nominal model) was calibrated on,
/// and records (`excavator-ctl calibrate`, docs/simulator.md "Plant version"). Its default soil
/// contact integration and a revision. `tests/plant_version.rs` pins the plant's behaviour for this
/// version: a change to the physics that moves it fails there until the version is bumped, and a bump
/// fails the check of the shipped artefacts until they are calibrated again.
pub const PLANT_VERSION: &str = "implicit-2";

/// Errors of the simulator library.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The machine file.
    #[error(transparent)]
    Machine(#[from] ConfigError),
    /// The scenario file.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// An effect setting.
    #[error("{origin}")]
    Effect {
        /// Where it came from (`--effect`, a file name).
        origin: String,
        /// The error.
        source: EffectError,
    },
    /// Building the plant.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// I/O (sockets, state log).
    #[error("{context}")]
    Io {
        /// What was being done.
        context: String,
        /// The error.
        source: std::io::Error,
    },
    /// The CAN bus.
    #[error("CAN bus: {0}")]
    Bus(String),
}

/// Result alias for the simulator library.
pub type Result<T> = std::result::Result<T, SimError>;

/// Everything needed to build a plant: machine, scenario and hidden effects.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The machine.
    pub machine: MachineConfig,
    /// The bench scenario.
    pub scenario: Scenario,
    /// Hidden effects (machine file, then scenario file, then command line).
    pub effects: EffectSet,
    /// The gateway's J1939 NAME: the machine file's `[gateway_name]` table (every field of a
    /// [`NameConfig`], each within its width), [`GATEWAY_NAME`] without one. The controller expects
    /// it (`[j1939.gateway_name]` of its config).
    pub gateway_name: Name,
}

/// The `[gateway_name]` table of a machine file ([`GATEWAY_NAME`] without one), checked field by
/// field.
fn gateway_name_from_table(text: &str, origin: &str) -> Result<Name> {
    #[derive(serde::Deserialize)]
    struct Wrapper {
        gateway_name: Option<NameConfig>,
    }
    let invalid = |line: Option<usize>, field: String, reason: String| {
        SimError::Machine(ConfigError::Invalid {
            origin: origin.to_owned(),
            line,
            field,
            reason,
        })
    };
    let w: Wrapper = toml::from_str(text).map_err(|e| {
        invalid(
            e.span()
                .map(|s| planner::toml_lines::line_of_offset(text, s.start)),
            "gateway_name".to_owned(),
            e.message().trim().to_owned(),
        )
    })?;
    match w.gateway_name {
        None => Ok(GATEWAY_NAME),
        Some(config) => config.name().map_err(|e| {
            let field = format!("gateway_name.{}", e.field);
            invalid(
                planner::toml_lines::line_of_field(text, &field),
                field,
                format!("{}: {}", e.value, e.rule),
            )
        }),
    }
}

fn effects_from_table(text: &str, origin: &str) -> Result<EffectSet> {
    #[derive(serde::Deserialize)]
    struct Wrapper {
        #[serde(default)]
        effects: std::collections::BTreeMap<String, f64>,
    }
    let w: Wrapper = toml::from_str(text).map_err(|e| SimError::Effect {
        origin: origin.to_owned(),
        source: EffectError::Syntax(e.message().to_owned()),
    })?;
    let mut set = EffectSet::nominal();
    for (name, value) in w.effects {
        set.set_by_name(&name, value)
            .map_err(|source| SimError::Effect {
                origin: format!("{origin}: [effects] {name}"),
                source,
            })?;
    }
    Ok(set)
}

/// The machine file's `hydraulics.transport_delay_s` within [`plant::MAX_TRANSPORT_DELAY_S`], as a
/// machine-file error with its line (the machine crate only requires it to be finite and >= 0).
fn check_transport_delay(cfg: &MachineConfig, text: &str, origin: &str) -> Result<()> {
    const FIELD: &str = "hydraulics.transport_delay_s";
    let delay = cfg.hydraulics.transport_delay_s;
    plant::TRANSPORT_DELAY_LIMITS.check(delay).map_err(|e| {
        SimError::Machine(ConfigError::Invalid {
            origin: origin.to_owned(),
            line: planner::toml_lines::line_of_field(text, FIELD),
            field: FIELD.to_owned(),
            reason: format!("{delay} s: {e}"),
        })
    })
}

impl SimConfig {
    /// Loads the machine (default `config/machine.toml`, compiled in) and the bench (default
    /// `config/bench.toml`, compiled in), overrides the seed, and applies `NAME=VALUE` effects.
    ///
    /// # Errors
    /// [`SimError`] naming the file, line and field, or the bad effect argument.
    pub fn load<S: AsRef<str>>(
        machine: Option<&Path>,
        bench: Option<&Path>,
        seed: Option<u64>,
        effect_args: &[S],
    ) -> Result<Self> {
        let mut gateway_name = GATEWAY_NAME;
        let (machine, mut effects) = match machine {
            Some(path) => {
                let origin = path.display().to_string();
                let text =
                    planner::config_file::read_text(path).map_err(|reason| SimError::Io {
                        context: format!("reading {origin}"),
                        source: std::io::Error::other(reason),
                    })?;
                let (machine_text, [effects_text, name_text]) =
                    planner::machine::split_simulator_tables(&text);
                let cfg = MachineConfig::from_toml_str_named(&machine_text, &origin)?;
                check_transport_delay(&cfg, &machine_text, &origin)?;
                gateway_name = gateway_name_from_table(&name_text, &origin)?;
                (cfg, effects_from_table(&effects_text, &origin)?)
            }
            None => (MachineConfig::default_machine()?, EffectSet::nominal()),
        };
        let mut scenario = match bench {
            Some(path) => Scenario::from_toml_file(path)?,
            None => Scenario::default_bench()?,
        };
        if let Some(seed) = seed {
            scenario.seed = seed;
        }
        let from_bench = scenario.effect_set().map_err(|source| SimError::Effect {
            origin: "bench [effects]".into(),
            source,
        })?;
        effects.merge(&from_bench);
        for arg in effect_args {
            effects
                .apply_arg(arg.as_ref())
                .map_err(|source| SimError::Effect {
                    origin: "--effect".into(),
                    source,
                })?;
        }
        let config = Self {
            machine,
            scenario,
            effects,
            gateway_name,
        };
        config.validate()?;
        Ok(config)
    }

    /// Checks what the plant's timing and memory depend on ([`plant::check_config`]): for a
    /// configuration assembled in code; [`Self::load`] already did, naming the files.
    ///
    /// # Errors
    /// [`SimError::Plant`] naming the field.
    pub fn validate(&self) -> Result<()> {
        Ok(plant::check_config(&self.machine, &self.scenario)?)
    }

    /// Builds the plant.
    ///
    /// # Errors
    /// [`SimError::Plant`], a value [`Self::validate`] refuses included.
    pub fn build(&self) -> Result<Plant> {
        Ok(Plant::new(&self.machine, &self.scenario, self.effects)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn machine_file_effects_table_is_split_out_keeping_lines() {
        let text = "a = 1\n[effects]\nvalve_deadband = 0.1\n[b]\nc = 2\n";
        let (m, [e, n]) = planner::machine::split_simulator_tables(text);
        assert_eq!(m.lines().count(), 5);
        assert!(!m.contains("valve_deadband") && m.contains("[b]"));
        let set = effects_from_table(&e, "m.toml").unwrap();
        assert_eq!(set.get(effects::Effect::ValveDeadband), 0.1);
        assert_eq!(gateway_name_from_table(&n, "m.toml").unwrap(), GATEWAY_NAME);
    }

    /// The default machine file with a `[gateway_name]` table whose `field` is `value`.
    fn machine_with_gateway_name(dir: &Path, field: &str, value: &str) -> std::path::PathBuf {
        let mut table = toml::to_string(&NameConfig::from(GATEWAY_NAME)).unwrap();
        let old = table
            .lines()
            .find(|l| l.starts_with(&format!("{field} =")))
            .unwrap()
            .to_owned();
        table = table.replace(&old, &format!("{field} = {value}"));
        let path = dir.join("m.toml");
        let text = format!(
            "{}\n[gateway_name]\n{table}",
            planner::machine::DEFAULT_MACHINE_TOML
        );
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn the_gateway_name_comes_from_the_machine_file_and_is_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = machine_with_gateway_name(dir.path(), "identity_number", "99");
        let cfg = SimConfig::load::<&str>(Some(&path), None, None, &[]).unwrap();
        assert_eq!(cfg.gateway_name.fields().identity_number, 99);
        assert_eq!(
            SimConfig::load::<&str>(None, None, None, &[])
                .unwrap()
                .gateway_name,
            GATEWAY_NAME
        );
        let path = machine_with_gateway_name(dir.path(), "vehicle_system", "200");
        let msg = SimConfig::load::<&str>(Some(&path), None, None, &[])
            .unwrap_err()
            .to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        let line = text
            .lines()
            .position(|l| l.starts_with("vehicle_system ="))
            .unwrap()
            + 1;
        assert!(
            msg.starts_with(&format!("{}:{line}:", path.display()))
                && msg.contains("gateway_name.vehicle_system")
                && msg.contains("7 bits"),
            "{msg}"
        );
    }

    #[test]
    fn load_defaults_and_reject_bad_effects() {
        let cfg = SimConfig::load::<&str>(None, None, Some(3), &[]).unwrap();
        assert_eq!(cfg.scenario.seed, 3);
        let err = SimConfig::load(None, None, None, &["nope=1"]).unwrap_err();
        let cause = std::error::Error::source(&err).map(ToString::to_string);
        assert!(
            cause.unwrap_or_default().contains("unknown effect"),
            "{err}"
        );
    }

    #[test]
    fn a_transport_delay_beyond_the_bound_is_refused_with_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.toml");
        let text = planner::machine::DEFAULT_MACHINE_TOML
            .replace("transport_delay_s = 0.06", "transport_delay_s = 1e9");
        assert_ne!(text, planner::machine::DEFAULT_MACHINE_TOML);
        std::fs::write(&path, &text).unwrap();
        let err = SimConfig::load::<&str>(Some(&path), None, None, &[]).unwrap_err();
        let line = text
            .lines()
            .position(|l| l.starts_with("transport_delay_s"))
            .unwrap()
            + 1;
        let msg = err.to_string();
        assert!(
            msg.starts_with(&format!(
                "{}:{line}: field `hydraulics.transport_delay_s`",
                path.display()
            )),
            "{msg}"
        );
        // Built in code, the plant refuses it too (it would queue 1e12 commands).
        let mut cfg = SimConfig::load::<&str>(None, None, None, &[]).unwrap();
        cfg.machine.hydraulics.transport_delay_s = 1e9;
        assert!(cfg.validate().is_err());
        assert!(cfg.build().is_err());
        let mut cfg = SimConfig::load::<&str>(None, None, None, &[]).unwrap();
        cfg.scenario.grid.cell_m = f64::NAN;
        assert!(matches!(
            cfg.build(),
            Err(SimError::Plant(PlantError::Config { .. }))
        ));
    }
}
