//! `netfi restore`: puts back what runs killed on this host left behind —
//! cleared cores (thread masks, interrupt affinities, the workqueue mask)
//! and the iceoryx2 resources of dead processes. Every `netfi run` does the
//! same first. With `--guard RECORD` it is the guardian a clearing process
//! starts: it waits for the record's owners to end and restores from it.

use crate::cli::RestoreArgs;
use anyhow::{Context, Result};
use netfi::host::record;

pub fn run(args: RestoreArgs) -> Result<()> {
    if let Some(path) = &args.guard {
        record::guard(path).with_context(|| format!("guarding {}", path.display()))?;
        return Ok(());
    }
    let dir = record::state_dir().context("the directory of core-clearing records")?;
    let done = record::restore_orphans(None).with_context(|| format!("restoring from the records in {}", dir.display()))?;
    for (path, r) in &done {
        println!(
            "restored {} placement(s) and widened {} thread(s) started during the run, from {}",
            r.undone,
            r.widened,
            path.display()
        );
    }
    let live = record::list(&dir);
    for path in &live {
        println!("left in place: {} (a run that owns it is still going)", path.display());
    }
    let cleaned = netfi::transport::cleanup_dead_runs(|_| true).context("removing iceoryx2 resources of dead processes")?;
    let removed: usize = cleaned.iter().map(|(_, r)| r.removed.len()).sum();
    if removed > 0 {
        println!("removed the iceoryx2 resources of {removed} dead process(es)");
    }
    if done.is_empty() && live.is_empty() && removed == 0 {
        println!("nothing to restore");
    }
    Ok(())
}
