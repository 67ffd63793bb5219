//! `netfi-emulator`: the emulator service alone (the same as `netfi emulator`).

fn main() -> anyhow::Result<()> {
    let args: netfi::service::args::EmulatorArgs = netfi::service::standalone_args("netfi-emulator", "The netfi emulator service")?;
    let report = netfi::service::emulator::main(&args)?;
    print!("{}", netfi::service::report::emulator_text(&report, &netfi::service::emulator::words(&args)));
    Ok(())
}
