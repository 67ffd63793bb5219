//! `netfi restore`: puts back what runs killed on this host left behind —
//! processes of runs whose owner is gone, cleared cores (thread masks,
//! interrupt affinities, the workqueue mask), and the shared memory and
//! iceoryx2 files of runs whose processes are all dead (this user's only).
//! Every `netfi run` does the same first. With `--guard RECORD` it is the
//! guardian a run or a clearing starts: it waits for the record's owners
//! to end and acts on it.

use crate::cli::RestoreArgs;
use anyhow::{Context, Result};
use netfi::host::guardian::{self, Guarded};
use netfi::host::record;
use netfi::transport::ipc;

pub fn run(args: RestoreArgs) -> Result<()> {
    if let Some(path) = &args.guard {
        let guarded = guardian::guard(path).with_context(|| format!("guarding {}", path.display()))?;
        if let Guarded::RunEnded { run, .. } = guarded {
            // The run's processes are gone now: so goes its shared memory.
            remove_shared_memory(|r| run.run_ids.iter().any(|id| id == r.as_str()))?;
        }
        return Ok(());
    }
    let dir = record::state_dir_resolved().context("the directory of records")?;
    if let Some(w) = dir.warning() {
        eprintln!("WARNING: {w}");
    }
    let mut said = false;
    for (path, r) in record::end_orphaned_runs().with_context(|| format!("ending runs whose owner is gone ({})", dir.path.display()))? {
        println!(
            "ended what was left of a run whose owner is gone: {} process(es) terminated, {} of them killed, from {}",
            r.ended.terminated,
            r.ended.killed,
            path.display()
        );
        said = true;
    }
    for (path, r) in record::restore_orphans(None).with_context(|| format!("restoring from the records in {}", dir.path.display()))? {
        println!("restored {} placement(s) and widened {} thread(s) started during the run, from {}", r.undone, r.widened, path.display());
        said = true;
    }
    for path in record::live_records().context("the directory of records")? {
        println!("left in place: {} (a run that owns it is still going)", path.display());
        said = true;
    }
    said |= remove_shared_memory(|_| true)?;
    if !said {
        println!("nothing to restore");
    }
    Ok(())
}

/// Removes every file of the runs `select` picks whose processes are all
/// dead, then the iceoryx2 resources of dead processes of the others; says
/// what it removed. Whether anything was.
fn remove_shared_memory(mut select: impl FnMut(&ipc::RunId) -> bool) -> Result<bool> {
    // First: the clean-up of dead nodes is how a run is seen to have died.
    let swept = ipc::remove_dead_run_files(&mut select).context("removing the files of dead runs")?;
    for (run, files) in &swept {
        println!("removed {files} shared-memory and iceoryx2 file(s) of the dead run {run}");
    }
    let cleaned = ipc::cleanup_dead_runs(&mut select).context("removing iceoryx2 resources of dead processes")?;
    let removed: usize = cleaned.iter().map(|(_, r)| r.removed.len()).sum();
    if removed > 0 {
        println!("removed the iceoryx2 resources of {removed} dead process(es)");
    }
    Ok(removed > 0 || !swept.is_empty())
}
