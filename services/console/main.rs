//! `netfi-console`: the console service alone (the same as `netfi console`).

use clap::Parser;

#[derive(Parser)]
#[command(name = "netfi-console", version, about = "The netfi console service")]
struct Cli {
    #[command(flatten)]
    args: netfi::service::args::ConsoleArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    netfi::host::process::die_with_runner()?;
    netfi::service::console::main(&cli.args)?;
    Ok(())
}
