//! `excavator-ctl generate-docs` (hidden): the manual pages (clap_mangen) and the shell completions
//! (clap_complete) written from the real command-line definition, for the Debian package
//! (scripts/package installs them).

use std::path::PathBuf;

use anyhow::Context as _;
use clap::CommandFactory as _;
use clap_complete::Shell;

/// Arguments of `generate-docs`.
#[derive(Debug, clap::Args)]
pub struct DocsArgs {
    /// Folder for the manual pages: `excavator-ctl.1` and one `excavator-ctl-SUBCOMMAND.1` per
    /// subcommand.
    #[arg(long, value_name = "DIR")]
    pub man: PathBuf,
    /// Folder for the completions of bash, zsh and fish.
    #[arg(long, value_name = "DIR")]
    pub completions: PathBuf,
}

/// The shells completions are written for.
pub const SHELLS: [Shell; 3] = [Shell::Bash, Shell::Zsh, Shell::Fish];

/// Writes the manual pages and completions of [`crate::cli::Cli`] into the folders of `args`.
///
/// # Errors
/// Creating a folder or writing a file.
pub fn generate(args: &DocsArgs) -> anyhow::Result<()> {
    let cmd = crate::cli::Cli::command();
    let name = cmd.get_name().to_owned();
    for dir in [&args.man, &args.completions] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    clap_mangen::generate_to(cmd.clone(), &args.man)
        .with_context(|| format!("writing the manual pages into {}", args.man.display()))?;
    for shell in SHELLS {
        clap_complete::generate_to(shell, &mut cmd.clone(), &name, &args.completions)
            .with_context(|| {
                format!(
                    "writing the {shell} completion into {}",
                    args.completions.display()
                )
            })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn man_pages_and_completions_cover_every_visible_subcommand() {
        let dir = tempfile::tempdir().unwrap();
        let args = DocsArgs {
            man: dir.path().join("man"),
            completions: dir.path().join("completions"),
        };
        generate(&args).unwrap();
        let main = std::fs::read_to_string(args.man.join("excavator-ctl.1")).unwrap();
        assert!(
            main.contains(".TH ") && main.contains(".SH SYNOPSIS"),
            "{main}"
        );
        let cmd = crate::cli::Cli::command();
        for sub in cmd.get_subcommands() {
            let page = args.man.join(format!("excavator-ctl-{}.1", sub.get_name()));
            assert_eq!(page.is_file(), !sub.is_hide_set(), "{}", page.display());
            if !sub.is_hide_set() {
                assert!(main.contains(&format!("excavator\\-ctl\\-{}(1)", sub.get_name())));
            }
        }
        let bash = std::fs::read_to_string(args.completions.join("excavator-ctl.bash")).unwrap();
        assert!(bash.contains("complete -F") && bash.contains("--config-dir"));
        assert!(args.completions.join("_excavator-ctl").is_file());
        assert!(args.completions.join("excavator-ctl.fish").is_file());
    }
}
