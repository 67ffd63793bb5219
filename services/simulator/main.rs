//! `netfi-simulator`: the simulator service alone (the same as `netfi simulator`).

fn main() -> anyhow::Result<()> {
    let args: netfi::service::args::SimulatorArgs = netfi::service::standalone_args("netfi-simulator", "The netfi simulator service")?;
    netfi::service::simulator::main(&args)?;
    Ok(())
}
