//! `netfi report DIR [--html]`: the report of a finished run, from what it
//! left in its output directory.

use crate::cli::ReportArgs;
use anyhow::Context;

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    if args.html {
        let path = netfi::html::write(&args.out_dir)?;
        println!("{}", path.display());
        return Ok(());
    }
    let path = args.out_dir.join("report.json");
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let report: netfi::service::report::RunReport =
        serde_json::from_slice(&bytes).with_context(|| format!("{}: not a run report", path.display()))?;
    print!("{}", report.to_text());
    Ok(())
}
