//! `netfi-emulator`: the emulator service alone (the same as `netfi emulator`).

use clap::Parser;

#[derive(Parser)]
#[command(name = "netfi-emulator", version, about = "The netfi emulator service")]
struct Cli {
    #[command(flatten)]
    args: netfi::service::args::EmulatorArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    netfi::host::process::die_with_runner()?;
    let report = netfi::service::emulator::main(&cli.args)?;
    print!("{}", netfi::service::report::emulator_text(&report));
    Ok(())
}
