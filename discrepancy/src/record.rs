//! `excavator-ctl discrepancy record-reference`: a reference recorded from healthy simulated
//! sessions of the default machine, the sessions users run (`excavator-ctl demo`'s defaults,
//! [`DemoArgs::defaults`], with only the seed, the digs, the folder and the progress bar set). The
//! shipped built-in reference (`config/nominal_reference.json`,
//! [`crate::reference::BUILTIN_REFERENCE_JSON`]) is its output; `analyse` without `--reference`
//! judges the default machine against it.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::Context as _;
use clap::Args;
use lab::demo::{DemoArgs, run_session};
use rayon::prelude::*;

use crate::analysis::load_reference;
use crate::reference::Recording;
use crate::session::{load_machine, load_model};

/// Arguments of `discrepancy record-reference`.
#[derive(Debug, Clone, Args)]
pub struct RecordReferenceArgs {
    /// Healthy default sessions.
    #[arg(long, default_value_t = 4, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub sessions: u32,
    /// Digs per session.
    #[arg(long, default_value_t = 16, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    pub digs: u32,
    /// Seed of the first session; the others follow it. Keep it clear of the seeds the reference
    /// will judge (`discrepancy eval --seed-base` refuses to overlap the built-in reference's).
    #[arg(long, default_value_t = 8501, value_name = "N")]
    pub seed_base: u64,
    /// The reference file to write (the built-in one: config/nominal_reference.json).
    #[arg(long, default_value = "out/reference.json", value_name = "FILE")]
    pub out: PathBuf,
    /// Folder for the generated sessions (default: `reference-sessions` beside `--out`).
    #[arg(long, value_name = "DIR")]
    pub sessions_dir: Option<PathBuf>,
}

impl RecordReferenceArgs {
    /// The defaults of the command line with `out` as the reference file.
    pub fn new(out: PathBuf) -> Self {
        Self {
            sessions: 4,
            digs: 16,
            seed_base: 8501,
            out,
            sessions_dir: None,
        }
    }

    /// The seeds of the sessions.
    pub fn seeds(&self) -> Vec<u64> {
        (0..u64::from(self.sessions))
            .map(|i| self.seed_base.saturating_add(i))
            .collect()
    }

    /// The `demo` arguments of every session: `demo`'s defaults ([`DemoArgs::defaults`]) with
    /// the seed, the digs, the folder and no progress bar.
    pub fn demo_args(&self) -> Vec<DemoArgs> {
        let dir = self.sessions_dir.clone().unwrap_or_else(|| {
            self.out
                .parent()
                .map_or_else(PathBuf::new, std::path::Path::to_path_buf)
                .join("reference-sessions")
        });
        self.seeds()
            .into_iter()
            .map(|seed| DemoArgs {
                digs: self.digs,
                seed: Some(seed),
                quiet: true,
                ..DemoArgs::defaults(dir.join(format!("healthy_s{seed}")))
            })
            .collect()
    }

    /// The command line that records this reference.
    pub fn command_line(&self) -> String {
        format!(
            "excavator-ctl discrepancy record-reference --sessions {} --digs {} --seed-base {} --out {}",
            self.sessions,
            self.digs,
            self.seed_base,
            self.out.display()
        )
    }
}

/// Generates the sessions, records their reference from the shipped nominal model and the
/// built-in machine (`analyse --reference DIR...` does the same: the calibration on them and the
/// residual levels with it), and writes it to `args.out`.
///
/// # Errors
/// Generating or reading a session; writing the file.
pub fn run_record(args: &RecordReferenceArgs) -> anyhow::Result<crate::reference::Reference> {
    let demos = args.demo_args();
    let sessions: Vec<PathBuf> = demos
        .par_iter()
        .map(|demo| {
            run_session(demo, &AtomicBool::new(false)).with_context(|| {
                format!("generating the healthy session {}", demo.out.display())
            })?;
            Ok(demo.out.clone())
        })
        .collect::<anyhow::Result<_>>()?;
    let machine = load_machine(None)?;
    let model = load_model(None)?;
    let mut reference =
        load_reference(&sessions, &machine, &model)?.context("no healthy sessions")?;
    let seeds = args.seeds();
    reference.source = vec![format!(
        "{} healthy default `demo` sessions of {} digs on the simulated default machine, seeds {}-{}",
        args.sessions,
        args.digs,
        seeds.first().copied().unwrap_or_default(),
        seeds.last().copied().unwrap_or_default(),
    )];
    reference.recording = Some(Recording {
        command: args.command_line(),
        seeds,
        digs: args.digs,
        plant_version: vcan_sim::PLANT_VERSION.to_string(),
    });
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&args.out, reference.to_json()?)
        .with_context(|| format!("writing {}", args.out.display()))?;
    Ok(reference)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference's sessions are `demo`'s defaults but for the seed, the digs, the folder and
    /// the progress bar: recorded on the sessions users run.
    #[test]
    fn record_reference_s_sessions_are_demo_s_defaults_but_for_seed_digs_out_and_quiet() {
        let args = RecordReferenceArgs::new(PathBuf::from("ref/reference.json"));
        let demos = args.demo_args();
        assert_eq!(demos.len(), 4);
        for (demo, seed) in demos.iter().zip(args.seeds()) {
            let expected = DemoArgs {
                digs: 16,
                seed: Some(seed),
                quiet: true,
                ..DemoArgs::defaults(PathBuf::from(format!(
                    "ref/reference-sessions/healthy_s{seed}"
                )))
            };
            assert_eq!(demo, &expected);
        }
    }

    /// The built-in reference is the output of the documented command on the shipped nominal
    /// model and the current plant: its command parses back to `record-reference`'s arguments
    /// with the seeds it records, and it judges with the model `analyse` starts from by default.
    #[test]
    fn the_builtin_reference_is_record_reference_s_on_the_shipped_model_and_plant() {
        let r = crate::reference::Reference::builtin().expect("the built-in reference parses");
        let rec = r.recording.as_ref().expect("it records how it was made");
        assert_eq!(
            r.model,
            crate::AugmentedModel::nominal().unwrap().provenance,
            "re-record it (docs/discrepancy.md) after the nominal model changes"
        );
        assert_eq!(rec.plant_version, vcan_sim::PLANT_VERSION);
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: RecordReferenceArgs,
        }
        let words: Vec<&str> = rec.command.split_whitespace().collect();
        assert_eq!(
            words[..3],
            ["excavator-ctl", "discrepancy", "record-reference"]
        );
        let parsed = <Cli as clap::Parser>::try_parse_from(&words[2..])
            .expect("the recorded command parses")
            .args;
        assert_eq!(parsed.seeds(), rec.seeds);
        assert_eq!(parsed.digs, rec.digs);
        assert_eq!(parsed.out, PathBuf::from("config/nominal_reference.json"));
    }
}
