//! Shell completions and manual pages, generated from the command-line
//! definition itself (`clap_complete`, `clap_mangen`), so they never drift
//! from the flags.

use anyhow::Context;
use clap::CommandFactory;
use std::io::Write;
use std::path::Path;

/// `netfi completions SHELL`: the completion script on standard output.
pub fn completions(shell: clap_complete::Shell) -> anyhow::Result<()> {
    let mut cmd = super::cli::Cli::command();
    let mut out = std::io::stdout().lock();
    clap_complete::generate(shell, &mut cmd, "netfi", &mut out);
    out.flush().context("writing the completion script to standard output")
}

/// `netfi man`: the top-level page on standard output; with `dir`, one page
/// per command (`netfi.1`, `netfi-run.1`, `netfi-scenario-check.1`, …).
pub fn man(dir: Option<&Path>) -> anyhow::Result<()> {
    let cmd = super::cli::Cli::command();
    match dir {
        None => {
            let mut out = std::io::stdout().lock();
            clap_mangen::Man::new(cmd).render(&mut out).context("writing the manual page to standard output")?;
            out.flush().context("writing the manual page to standard output")
        }
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            clap_mangen::generate_to(cmd, dir).with_context(|| format!("writing manual pages into {}", dir.display()))?;
            println!("manual pages written to {}", dir.display());
            Ok(())
        }
    }
}
