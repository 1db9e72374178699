//! `excavator-ctl model generate-data`: Autodig digs in the simulator from varied starts (bench
//! geometry, cohesion, start distance and bucket angle, hardness index), each written as a `candump
//! -L` trace, so `model train` reads the same thing as a trace recorded by `run` or `demo`.

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use firmware_bridge::trace::TraceWriter;
use rayon::prelude::*;

use super::sim_dig::{SimDig, random_setups, run_sim_dig};

/// Arguments of `model generate-data`.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Output folder (one `dig_NNN.log` per dig and `setups.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of digs.
    #[arg(long, default_value_t = 60)]
    pub digs: usize,
    /// Seed of the starts, terrain and sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print every dig's statistics.
    #[arg(long)]
    pub verbose: bool,
}

/// Runs `model generate-data`.
///
/// # Errors
/// No digs asked for, simulator errors, writing the traces.
pub fn run(a: &GenerateArgs) -> anyhow::Result<()> {
    if a.digs == 0 {
        bail!("--digs must be at least 1");
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let setups = random_setups(a.digs, a.seed, true)?;
    let bar = indicatif::ProgressBar::new(setups.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} digs {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let results: Vec<anyhow::Result<SimDig>> = setups
        .par_iter()
        .map(|s| {
            let path = a.out.join(format!("dig_{:03}.log", s.index));
            let file =
                File::create(&path).with_context(|| format!("creating {}", path.display()))?;
            let mut w = TraceWriter::new(BufWriter::new(file), "vcan0", true);
            let dig = run_sim_dig(s, Some(&mut w))?;
            w.flush()?;
            bar.inc(1);
            Ok(dig)
        })
        .collect();
    bar.finish_and_clear();
    let mut volume = 0.0;
    let mut time = 0.0;
    for r in &results {
        let d = r.as_ref().map_err(|e| anyhow::anyhow!("{e:#}"))?;
        volume += d.swept_volume_m3;
        time += d.time_s;
        if a.verbose {
            let first = d
                .samples
                .first()
                .map_or([0.0; 2], |s| [s.tip_x_m, s.tip_z_m]);
            let min_z = d
                .samples
                .iter()
                .map(|s| s.tip_z_m)
                .fold(f64::INFINITY, f64::min);
            println!(
                "  dig {:>3}: start r {:.2} z {:.2}, lowest z {:.2}, {:.2} s, swept {:.2} m^3, bucket {:.2} m^3, {:.0} kJ, end {:?}",
                d.setup.index,
                first[0],
                first[1],
                min_z,
                d.time_s,
                d.swept_volume_m3,
                d.bucket_volume_m3,
                d.energy_j * 1e-3,
                d.end
            );
        }
    }
    std::fs::write(
        a.out.join("setups.json"),
        serde_json::to_string_pretty(&setups)?,
    )?;
    let n = setups.len() as f64;
    println!(
        "wrote {} dig traces to {} (mean dig {:.2} s, swept {:.2} m^3)",
        setups.len(),
        a.out.display(),
        time / n,
        volume / n
    );
    Ok(())
}
