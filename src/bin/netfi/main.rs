//! The `netfi` command line: a thin wrapper over the library.

mod cli;
mod ctl;
mod docs;
mod export;
mod fit;
mod report;
mod restore;
mod scenario;
mod study;

use clap::Parser;

fn main() -> std::process::ExitCode {
    // Output piped into `head` and closed early ends the program quietly, as
    // command-line tools do, instead of a panic on the broken pipe.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = cli::Cli::parse();
    if matches!(args.command, cli::Command::Console(_) | cli::Command::Emulator(_) | cli::Command::Simulator(_)) {
        if let Err(e) = netfi::host::process::die_with_runner() {
            eprintln!("netfi: {e}");
            return std::process::ExitCode::FAILURE;
        }
    }
    let result = match args.command {
        cli::Command::Scenario(cmd) => scenario::run(cmd),
        cli::Command::Run(a) => run(&a),
        cli::Command::Console(a) => netfi::service::console::main(&a).map(|_| ()).map_err(Into::into),
        cli::Command::Emulator(a) => netfi::service::emulator::main(&a).map(|r| print!("{}", netfi::service::report::emulator_text(&r, &netfi::service::emulator::words(&a)))).map_err(Into::into),
        cli::Command::Simulator(a) => netfi::service::simulator::main(&a).map(|_| ()).map_err(Into::into),
        cli::Command::Fit(cmd) => fit::run(cmd),
        cli::Command::Export(cmd) => export::run(cmd),
        cli::Command::Restore(a) => restore::run(a),
        cli::Command::Ui(a) => ui(a),
        cli::Command::Completions { shell } => docs::completions(shell),
        cli::Command::Man { dir } => docs::man(dir.as_deref()),
        cli::Command::Report(a) => report::run(&a),
        cli::Command::Ctl(a) => ctl::run(a),
        cli::Command::Study(a) => study::run(a),
        cli::Command::Ros2(cmd) => netfi::service::ros2::bag::run(cmd).map_err(Into::into),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // Not `eprintln!`: on a full disk a log on it cannot take the
            // message, and a panic would hide the failure behind exit 101.
            let _ = std::io::Write::write_fmt(&mut std::io::stderr(), format_args!("error: {e:#}\n"));
            std::process::ExitCode::FAILURE
        }
    }
}

/// `netfi run`: the report on stdout; a failure exit status when a frame is
/// unaccounted for or a process failed.
fn run(args: &netfi::service::args::RunArgs) -> anyhow::Result<()> {
    let report = netfi::service::run::run(args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    if !report.frames.balanced || !report.faults.is_empty() {
        // Named here, not "above": stdout may be a file, or a page's log.
        let said = if report.faults.is_empty() { "not every frame is accounted for".to_string() } else { report.faults.join("; ") };
        anyhow::bail!("the run had faults: {said} (its report: {})", netfi::service::report::files::report_said(&report.files.report_json));
    }
    Ok(())
}

/// `netfi ui`: serves until interrupted.
fn ui(a: cli::UiArgs) -> anyhow::Result<()> {
    let last_core = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).max().unwrap_or(0);
    Ok(netfi::ui::serve(netfi::ui::UiOptions {
        bind: std::net::SocketAddr::new(a.bind, a.port),
        out_dir: a.out,
        netfi: std::env::current_exe()?,
        emulator_core: a.emulator_core.unwrap_or(last_core),
        no_token: a.no_token,
        allow_hosts: a.allow_host,
    })?)
}
