//! `netfi-simulator`: the simulator service alone (the same as `netfi simulator`).

use clap::Parser;

#[derive(Parser)]
#[command(name = "netfi-simulator", version, about = "The netfi simulator service")]
struct Cli {
    #[command(flatten)]
    args: netfi::service::args::SimulatorArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    netfi::host::process::die_with_runner()?;
    netfi::service::simulator::main(&cli.args)?;
    Ok(())
}
