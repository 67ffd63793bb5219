//! `netfi report DIR [--html]`: the report of a finished run, from what it
//! left in its output directory: the run's `report.json`, or, for a run
//! started by hand (a stand-alone emulator and its clients), the report
//! assembled from the services' own. The text report fails (exit status
//! 1) where the run had a fault or a frame is unaccounted for, as `netfi
//! run` does; the page is written whatever the run was.

use crate::cli::ReportArgs;

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    if args.html {
        let path = netfi::html::write(&args.out_dir)?;
        println!("{}", path.display());
        return Ok(());
    }
    let report = netfi::service::report::RunReport::of_dir(&args.out_dir)?;
    print!("{}", report.to_text());
    if !report.frames.balanced || !report.faults.is_empty() {
        // Named here, not "above": stdout may be a file.
        let said = if report.faults.is_empty() { "not every frame is accounted for".to_string() } else { report.faults.join("; ") };
        anyhow::bail!("the run in {} had faults: {said}", args.out_dir.display());
    }
    Ok(())
}
