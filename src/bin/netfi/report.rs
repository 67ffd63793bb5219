//! `netfi report DIR [--html]`: the report of a finished run, from what it
//! left in its output directory: the run's `report.json`, or, for a run
//! started by hand (a stand-alone emulator and its clients), the report
//! assembled from the services' own.

use crate::cli::ReportArgs;

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    if args.html {
        let path = netfi::html::write(&args.out_dir)?;
        println!("{}", path.display());
        return Ok(());
    }
    let report = netfi::service::report::RunReport::of_dir(&args.out_dir)?;
    print!("{}", report.to_text());
    Ok(())
}
