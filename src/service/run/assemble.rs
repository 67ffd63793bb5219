//! The run's report, from what the services wrote and how each process
//! ended; written where the run was asked to write it.

use super::procs::{Proc, Procs};
use crate::host::Steal;
use crate::service::plan::Plan;
use crate::service::report::RunReport;
use std::path::PathBuf;

/// The run's report: the services' reports joined; with several streams,
/// each stream's (also `<out>/stream-K/report.json`) and the total, under
/// stream 0's.
pub fn assemble(plan: &Plan, procs: &Procs, duration_s: f64, steal: Steal, interrupted: bool) -> RunReport {
    if plan.streams.len() == 1 {
        let faults = procs.all().flat_map(Proc::faults).collect();
        let processes = procs.all().map(Proc::end).collect();
        return RunReport::assemble(plan, duration_s, steal, processes, faults, interrupted);
    }
    let mut reports = Vec::new();
    for (k, s) in plan.streams.iter().enumerate() {
        let own = [&procs.consoles[k], &procs.emulator, &procs.simulators[k]];
        let faults = own.iter().flat_map(|p| p.faults()).collect();
        let processes = own.iter().map(|p| p.end()).collect();
        let sp = Plan { run_id: s.run_id.clone(), out: s.out.clone(), spec: s.spec.clone(), seed: s.seed, scenario_path: s.scenario_path.clone(), ..plan.clone() };
        let mut r = RunReport::assemble(&sp, duration_s, steal, processes, faults, interrupted);
        let path = r.files.report_json.clone();
        write(&mut r, &[path]);
        reports.push(r);
    }
    RunReport::join_streams(reports, procs.all().map(Proc::end).collect(), &plan.out)
}

/// Writes `report` as JSON to each of `paths`. A report that cannot be
/// written (a full disk) is a fault of the run; the report is still
/// returned, for stdout.
pub fn write(report: &mut RunReport, paths: &[PathBuf]) {
    let json = match serde_json::to_vec_pretty(&*report) {
        Ok(j) => j,
        Err(e) => return report.faults.push(format!("the report could not be serialized: {e}")),
    };
    for path in paths {
        if let Err(e) = crate::service::report::write_whole(path, &json) {
            report.faults.push(format!("writing {}: {e}", path.display()));
        }
    }
}
