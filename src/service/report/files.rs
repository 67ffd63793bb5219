//! A run's files whole or named as cut: a file is written as
//! `NAME.partial` and renamed to `NAME` once every byte is on the disk, so
//! a `NAME.partial` left in a run's directory is a file cut short (its
//! writer was killed, or its disk was full), and the run's report names it.

use std::io::Write;
use std::path::{Path, PathBuf};

/// The suffix of a file still being written, or cut.
pub const PARTIAL_SUFFIX: &str = ".partial";

/// Why a file could not be written whole. Each names the file as it is on
/// disk.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// Creating, writing or syncing `NAME.partial` failed (a full disk);
    /// what was written stays there, named as cut.
    #[error("writing {}: {source}", path.display())]
    Write { path: PathBuf, source: std::io::Error },
    /// The whole file could not take its own name; it stays `NAME.partial`.
    #[error("renaming {} to {}: {source}", from.display(), to.display())]
    Rename { from: PathBuf, to: PathBuf, source: std::io::Error },
}

/// The name `path` has while it is written, and keeps if it is cut.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(PARTIAL_SUFFIX);
    PathBuf::from(name)
}

/// Writes `bytes` as the whole of `path`: into `path.partial`, synced,
/// then renamed, so that `path` is either whole or not there (the report
/// of a run on a full disk is not left with 0 bytes).
pub fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    let partial = partial_path(path);
    let written = std::fs::File::create(&partial).and_then(|mut f| f.write_all(bytes).and_then(|_| f.sync_all()));
    written.map_err(|source| WriteError::Write { path: partial.clone(), source })?;
    std::fs::rename(&partial, path).map_err(|source| WriteError::Rename { from: partial, to: path.to_path_buf(), source })
}

/// The cut files under `dir` and its subdirectories (a run's `stream-K/`):
/// every `NAME.partial`, sorted. Symbolic links are not followed; a
/// directory that cannot be read is an error naming it.
pub fn cut_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    cut_files_to(dir, usize::MAX)
}

/// The cut files in `dir` and in its subdirectories down to `depth` (0:
/// `dir` alone).
fn cut_files_to(dir: &Path, depth: usize) -> std::io::Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    let mut dirs = vec![(dir.to_path_buf(), 0)];
    let named = |d: &Path, e: std::io::Error| std::io::Error::new(e.kind(), format!("reading {}: {e}", d.display()));
    while let Some((d, below)) = dirs.pop() {
        for entry in std::fs::read_dir(&d).map_err(|e| named(&d, e))? {
            let entry = entry.map_err(|e| named(&d, e))?;
            let kind = entry.file_type().map_err(|e| named(&d, e))?;
            let path = entry.path();
            if kind.is_dir() && below < depth {
                dirs.push((path, below + 1));
            } else if kind.is_file() && is_partial(&path) {
                found.push(path);
            }
        }
    }
    found.sort();
    Ok(found)
}

/// Whether `path` names a file still being written, or cut.
pub fn is_partial(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.len() > PARTIAL_SUFFIX.len() && n.ends_with(PARTIAL_SUFFIX))
}

/// The faults a run's report gives for the cut files under `dir`, one
/// each, or one saying the directory could not be searched.
pub fn cut_faults(dir: &Path) -> Vec<String> {
    faults_of(cut_files(dir))
}

/// The faults for the cut files in `dir` itself (a run of several
/// streams: each stream's report names those in its directory).
pub fn cut_faults_here(dir: &Path) -> Vec<String> {
    faults_of(cut_files_to(dir, 0))
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

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("netfi-report-files-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

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

    #[test]
    fn a_file_written_whole_replaces_the_old_one_and_a_failed_one_leaves_no_whole_name() {
        let d = dir("whole");
        let path = d.join("report.json");
        std::fs::write(&path, b"old").unwrap();
        write_whole(&path, b"{\"new\": 1}").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"{\"new\": 1}");
        assert!(!partial_path(&path).exists());
        // The whole name taken by a directory: the rename fails, the bytes
        // stay under the cut name and the error names both.
        let blocked = d.join("blocked.json");
        std::fs::create_dir_all(blocked.join("keep")).unwrap();
        let e = write_whole(&blocked, b"{}").unwrap_err();
        assert!(matches!(e, WriteError::Rename { .. }), "{e}");
        assert!(e.to_string().contains(&blocked.display().to_string()), "{e}");
        assert_eq!(std::fs::read(partial_path(&blocked)).unwrap(), b"{}");
        let e = write_whole(&d.join("no-dir/report.json"), b"{}").unwrap_err();
        assert!(e.to_string().contains("no-dir/report.json.partial"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }
}
