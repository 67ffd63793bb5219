//! A run's files whole or named as cut ([`crate::durable`]: a file is
//! written as `NAME.partial` and renamed to `NAME` once every byte is on
//! the disk, so a `NAME.partial` left in a run's directory is a file cut
//! short — its writer was killed, or its disk was full); here, the cut
//! files as faults of the run's report.

pub use crate::durable::{cut_files, is_partial, partial_path, write_whole, DurableError as WriteError, PARTIAL_SUFFIX};
use std::path::PathBuf;

/// The mark `netfi run` leaves in each of its run's directories from its
/// start until it has written the run's report: found without a report,
/// it says the runner was killed (or failed) before the end.
pub const UNFINISHED_MARK: &str = "run.unfinished";

/// The fault a rebuilt report gives for a run whose runner left its
/// [`UNFINISHED_MARK`] in `dir` (what the mark says of the runner with
/// it), or `None` where there is no mark.
pub fn unfinished(dir: &std::path::Path) -> Option<String> {
    use std::io::Read;
    let mark = dir.join(UNFINISHED_MARK);
    let d = crate::durable::Dir::open(dir).ok()?;
    d.entry(UNFINISHED_MARK.as_ref()).ok()??;
    // Its first line only, and never through a link: a report may be made
    // by another user than the directory's.
    let mut said = String::new();
    if let Ok(f) = d.open_read(UNFINISHED_MARK.as_ref()) {
        let _ = f.take(200).read_to_string(&mut said);
    }
    let said = said.lines().next().unwrap_or("").trim();
    let who = if said.is_empty() { String::new() } else { format!(" ({said})") };
    Some(format!("interrupted: the runner of this run did not finish it{who}: it was killed, or failed before writing the run's report ({} is still there); this report is rebuilt from what the run's processes left and may be short", mark.display()))
}

/// Where a run's report is, as the run's text and its last words say it:
/// `path` when whole; its cut `.partial` (named as cut) when only that is
/// there; and that it was not written when neither is.
pub fn report_said(path: &std::path::Path) -> String {
    if path.exists() {
        return path.display().to_string();
    }
    let cut = partial_path(path);
    if cut.exists() {
        return format!("{} (cut: not written whole)", cut.display());
    }
    format!("{} (not written)", path.display())
}

/// The faults a run's report gives for the cut files under `dir`, one
/// each, or one saying the directory could not be searched.
pub fn cut_faults(dir: &std::path::Path) -> Vec<String> {
    faults_of(cut_files(dir))
}

/// The faults for the cut files in `dir` itself (a run of several
/// streams: each stream's report names those in its directory).
pub fn cut_faults_here(dir: &std::path::Path) -> Vec<String> {
    faults_of(crate::durable::cut_files_to(dir, 0))
}

fn faults_of(cut: std::io::Result<Vec<PathBuf>>) -> Vec<String> {
    match cut {
        Ok(cut) => cut.iter().map(|p| format!("cut file: {} (its writer stopped before it was whole)", p.display())).collect(),
        Err(e) => vec![format!("cut files not looked for: {e}")],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::dir;

    #[test]
    fn cut_files_are_found_in_the_run_and_its_streams_and_whole_ones_are_not() {
        let d = dir("cut");
        std::fs::create_dir_all(d.join("stream-1")).unwrap();
        for f in ["trace.csv", "report.json", "stream-1/received.csv.partial", "trace_emulator.csv.partial", ".partial"] {
            std::fs::write(d.join(f), b"x").unwrap();
        }
        let cut = cut_files(&d).unwrap();
        assert_eq!(cut, vec![d.join("stream-1/received.csv.partial"), d.join("trace_emulator.csv.partial")]);
        let faults = cut_faults(&d);
        assert_eq!(faults.len(), 2);
        assert!(faults[0].starts_with(&format!("cut file: {}", d.join("stream-1/received.csv.partial").display())), "{faults:?}");
        assert_eq!(cut_faults_here(&d).len(), 1, "the streams' own are theirs");
        let gone = d.join("not-there");
        assert!(cut_faults(&gone)[0].contains(&gone.display().to_string()));
        std::fs::remove_dir_all(&d).ok();
    }
}
