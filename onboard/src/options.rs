//! The options a session was started with, kept in its folder (`run_options.json`), so that
//! `run --resume DIR` alone goes on with the same interface, files and settings.
//!
//! A resumed run takes every option it is not given from the saved ones; an option given again must
//! name the same value (paths compare as absolute paths), else the run is refused naming the option.
//! Four may change between a session and its resumption, as the session's identity allows
//! ([`crate::run::session_identity`]): `--digs`, `--listen-only`, `--key-file` (a machine's key
//! may be re-provisioned) and `--control-socket`; the last two default to the saved ones too.

use std::fmt::Debug;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use firmware_bridge::transport::TimeScale;
use serde::{Deserialize, Serialize};

use crate::run::RunArgs;
use crate::summary::DemoStrategy;

/// The file in a session folder.
pub const OPTIONS_FILE_NAME: &str = "run_options.json";

/// The saved file's format: a file of another format is refused.
const FORMAT: u32 = 1;

/// The options of `run` that make the session: what `--resume DIR` takes from its folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedOptions {
    /// The file's format, 1 (a file of another format is refused).
    pub format: u32,
    /// `--iface`.
    pub iface: String,
    /// `--machine`, absolute.
    pub machine: Option<PathBuf>,
    /// `--maps`, absolute.
    pub maps: Option<PathBuf>,
    /// `--config`, absolute.
    pub config: Option<PathBuf>,
    /// `--trace`, absolute.
    pub trace: Option<PathBuf>,
    /// `--scan-addr`.
    pub scan_addr: Option<String>,
    /// `--strategy` (the default when not given).
    pub strategy: DemoStrategy,
    /// `--site`, absolute.
    pub site: Option<PathBuf>,
    /// `--seed`.
    pub seed: Option<u64>,
    /// `--planner`, absolute.
    pub planner: Option<PathBuf>,
    /// `--hardness`, absolute.
    pub hardness: Option<PathBuf>,
    /// `--time-scale` (the default when not given).
    pub time_scale: f64,
    /// `--config-dir`, absolute.
    pub config_dir: Option<PathBuf>,
    /// `--profile`, absolute.
    pub profile: Option<PathBuf>,
    /// `--key-file`, absolute (the path, never the key).
    pub key_file: Option<PathBuf>,
    /// `--control-socket`, absolute.
    pub control_socket: Option<PathBuf>,
}

/// `path` as an absolute path (from the working directory), unchanged when that fails.
fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_owned())
}

impl SavedOptions {
    /// The options of `args` (a session's first run, with its interface).
    #[must_use]
    pub fn of(args: &RunArgs, iface: &str) -> Self {
        let abs = |p: &Option<PathBuf>| p.as_deref().map(absolute);
        Self {
            format: FORMAT,
            iface: iface.to_owned(),
            machine: abs(&args.machine),
            maps: abs(&args.maps),
            config: abs(&args.config),
            trace: abs(&args.trace),
            scan_addr: args.scan_addr.clone(),
            strategy: args.strategy(),
            site: abs(&args.site),
            seed: args.seed,
            planner: abs(&args.planner),
            hardness: abs(&args.hardness),
            time_scale: args.time_scale().get(),
            config_dir: abs(&args.config_dir),
            profile: abs(&args.profile),
            key_file: abs(&args.key_file),
            control_socket: abs(&args.control_socket),
        }
    }

    /// Writes the options into the session folder `dir`.
    ///
    /// # Errors
    /// The file cannot be written (named).
    pub fn save(&self, dir: &Path) -> anyhow::Result<()> {
        let path = dir.join(OPTIONS_FILE_NAME);
        let text = serde_json::to_string_pretty(self).context("serializing the run's options")?;
        std::fs::write(&path, text + "\n").with_context(|| format!("writing {}", path.display()))
    }

    /// The options saved in the session folder `dir`; `None` when it has none (a session saved
    /// before the options were kept: its run must be given them all again).
    ///
    /// # Errors
    /// An unreadable or invalid file, naming it and the field.
    pub fn load(dir: &Path) -> anyhow::Result<Option<Self>> {
        let path = dir.join(OPTIONS_FILE_NAME);
        if !path.exists() {
            return Ok(None);
        }
        let text = planner::config_file::read_text(&path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let saved: Self = serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", path.display(), e.line()))?;
        if saved.format != FORMAT {
            anyhow::bail!(
                "{}: format {} where this excavator-ctl reads {FORMAT}",
                path.display(),
                saved.format
            );
        }
        TimeScale::new(saved.time_scale)
            .map_err(|e| anyhow::anyhow!("{}: time_scale: {e}", path.display()))?;
        Ok(Some(saved))
    }
}

/// Takes `saved` into `given` when the option was not given; refuses a given value that differs.
fn take<T: PartialEq + Debug>(
    option: &str,
    file: &Path,
    given: &mut Option<T>,
    saved: Option<T>,
) -> anyhow::Result<()> {
    match (given.as_ref(), saved) {
        (Some(g), s) if s.as_ref() != Some(g) => anyhow::bail!(
            "--{option} {g:?} differs from the session's {} ({}): a resumed session goes on with \
             the options it was started with; leave --{option} out",
            s.map_or_else(|| "default".to_owned(), |s| format!("{s:?}")),
            file.display()
        ),
        (None, s) => {
            *given = s;
            Ok(())
        }
        _ => Ok(()),
    }
}

/// `args` with `--resume DIR`'s saved options filled in ([`SavedOptions::load`]); unchanged without
/// `--resume` or without saved options.
///
/// # Errors
/// An unreadable saved file, or an option given that differs from the saved one, naming it.
pub fn resumed(mut args: RunArgs) -> anyhow::Result<RunArgs> {
    let Some(dir) = args.resume.clone() else {
        return Ok(args);
    };
    let Some(saved) = SavedOptions::load(&dir)? else {
        return Ok(args);
    };
    let file = dir.join(OPTIONS_FILE_NAME);
    let file = file.as_path();
    take("iface", file, &mut args.iface, Some(saved.iface))?;
    for (option, given, saved) in [
        ("machine", &mut args.machine, saved.machine),
        ("maps", &mut args.maps, saved.maps),
        ("config", &mut args.config, saved.config),
        ("trace", &mut args.trace, saved.trace),
        ("site", &mut args.site, saved.site),
        ("planner", &mut args.planner, saved.planner),
        ("hardness", &mut args.hardness, saved.hardness),
        ("config-dir", &mut args.config_dir, saved.config_dir),
        ("profile", &mut args.profile, saved.profile),
    ] {
        let mut abs = given.as_deref().map(absolute);
        take(option, file, &mut abs, saved)?;
        *given = abs;
    }
    take("scan-addr", file, &mut args.scan_addr, saved.scan_addr)?;
    take("strategy", file, &mut args.strategy, Some(saved.strategy))?;
    take("seed", file, &mut args.seed, saved.seed)?;
    let mut scale = args.time_scale.map(TimeScale::get);
    take("time-scale", file, &mut scale, Some(saved.time_scale))?;
    args.time_scale = Some(TimeScale::new(saved.time_scale)?);
    // May change: the saved ones unless given.
    if args.key_file.is_none() {
        args.key_file = saved.key_file;
    }
    if args.control_socket.is_none() {
        args.control_socket = saved.control_socket;
    }
    Ok(args)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn first_run(dir: &Path) -> RunArgs {
        let mut a = RunArgs::new("vcan3");
        a.strategy = Some(DemoStrategy::Planned);
        a.time_scale = Some(TimeScale::new(2.0).unwrap_or_default());
        a.site = Some(PathBuf::from("site.toml"));
        a.scan_addr = Some("127.0.0.1:5000".to_owned());
        a.key_file = Some(PathBuf::from("/etc/excavator/key"));
        a.out = Some(dir.to_owned());
        a
    }

    fn resume_of(dir: &Path) -> RunArgs {
        let mut a = RunArgs::new("vcan3");
        a.iface = None;
        a.resume = Some(dir.to_owned());
        a
    }

    #[test]
    fn resume_alone_takes_the_saved_options() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let first = first_run(dir.path());
        SavedOptions::of(&first, "vcan3")
            .save(dir.path())
            .unwrap_or_else(|e| panic!("{e}"));
        let r = resumed(resume_of(dir.path())).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(r.iface.as_deref(), Some("vcan3"));
        assert_eq!(r.strategy(), DemoStrategy::Planned);
        assert_eq!(r.time_scale().get(), 2.0);
        assert_eq!(r.site, Some(absolute(Path::new("site.toml"))));
        assert_eq!(r.scan_addr, first.scan_addr);
        assert_eq!(r.machine, None);
        assert_eq!(r.key_file, first.key_file);
        // Given again with the same values (a relative path as the absolute one): accepted.
        let mut same = resume_of(dir.path());
        same.site = Some(PathBuf::from("site.toml"));
        same.strategy = Some(DemoStrategy::Planned);
        same.digs = Some(9);
        same.key_file = Some(PathBuf::from("/etc/excavator/new.key"));
        let r = resumed(same).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(r.digs, Some(9));
        assert_eq!(r.key_file, Some(PathBuf::from("/etc/excavator/new.key")));
    }

    #[test]
    fn a_differing_option_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        SavedOptions::of(&first_run(dir.path()), "vcan3")
            .save(dir.path())
            .unwrap_or_else(|e| panic!("{e}"));
        type Change = fn(&mut RunArgs);
        let cases: [(&str, Change); 5] = [
            ("--strategy", |a| a.strategy = Some(DemoStrategy::Fixed)),
            ("--time-scale", |a| {
                a.time_scale = Some(TimeScale::REAL_TIME)
            }),
            ("--iface", |a| a.iface = Some("can0".to_owned())),
            ("--machine", |a| {
                a.machine = Some(PathBuf::from("other.toml"))
            }),
            ("--site", |a| {
                a.site = Some(PathBuf::from("/elsewhere/site.toml"))
            }),
        ];
        for (option, change) in cases {
            let mut a = resume_of(dir.path());
            change(&mut a);
            let e = resumed(a).map(|_| ()).unwrap_err().to_string();
            assert!(e.starts_with(option), "{option}: {e}");
            assert!(e.contains(OPTIONS_FILE_NAME), "{e}");
        }
    }

    #[test]
    fn a_broken_options_file_is_named() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(
            dir.path().join(OPTIONS_FILE_NAME),
            "{\n\"format\": 1,\n\"x\": 2}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = resumed(resume_of(dir.path()))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("{OPTIONS_FILE_NAME}:3")), "{e}");
    }
}
