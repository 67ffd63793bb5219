//! `netfi-console`: the console service alone (the same as `netfi console`).

fn main() -> anyhow::Result<()> {
    let args: netfi::service::args::ConsoleArgs = netfi::service::standalone_args("netfi-console", "The netfi console service")?;
    netfi::service::console::main(&args)?;
    Ok(())
}
