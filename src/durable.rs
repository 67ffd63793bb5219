//! Files that are whole or say they are cut.
//!
//! A run's files (its traces, `received.csv`, `video_received.csv`, the
//! histogram logs, its JSON reports) are written under a temporary name,
//! `NAME.partial`, and renamed to `NAME` only once every byte is written,
//! flushed and synced to the disk. So:
//!
//! - a file under its own name is **whole**;
//! - a file still called `NAME.partial` is **cut**: its writer was killed,
//!   or its disk was full, or it could not be synced; it holds what was
//!   written up to then (a streamed CSV up to its last flush) and is kept,
//!   not removed, so what it has is not lost and [`cut_files`] can name it.
//!
//! Creating `NAME.partial` removes a `NAME` left by an earlier run into the
//! same directory, so a cut file never sits beside a stale whole one.
//!
//! [`PartialFile`] streams a file this way ([`PartialFile::commit`] ends
//! it); [`write_whole`] writes one in a single call (a JSON report).

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// The suffix of a file still being written, or cut.
pub const PARTIAL_SUFFIX: &str = ".partial";

/// Why a file could not be written whole. Each names the file as it is on
/// disk (the `.partial` name, which then stays as the mark of a cut file).
#[derive(Debug, thiserror::Error)]
pub enum DurableError {
    /// `NAME.partial` could not be created (or a stale `NAME` removed).
    #[error("creating {}: {source}", .path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// Writing, flushing or syncing failed (a full disk: `No space left on
    /// device`); the file is cut and keeps its `.partial` name.
    #[error("writing {}: {source}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// The whole file could not be renamed to its own name; it stays as
    /// `.partial`.
    #[error("renaming {} to {}: {source}", .from.display(), .to.display())]
    Rename {
        /// The written file.
        from: PathBuf,
        /// Its own name.
        to: PathBuf,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
}

/// The name a file of `path` has while it is written (and if it is cut).
pub fn partial_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(PARTIAL_SUFFIX);
    PathBuf::from(p)
}

/// A file written as `NAME.partial` and renamed to `NAME` by
/// [`PartialFile::commit`]. Dropped without a commit, it stays cut.
#[derive(Debug)]
pub struct PartialFile {
    file: File,
    path: PathBuf,
    partial: PathBuf,
}

impl PartialFile {
    /// Creates (truncates) `path.partial`, after removing a `path` an
    /// earlier run left.
    pub fn create(path: &Path) -> Result<PartialFile, DurableError> {
        let partial = partial_path(path);
        match std::fs::remove_file(path) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(source) => return Err(DurableError::Create { path: path.to_path_buf(), source }),
        }
        let file = File::create(&partial).map_err(|source| DurableError::Create { path: partial.clone(), source })?;
        Ok(PartialFile { file, path: path.to_path_buf(), partial })
    }

    /// The name the file has once whole.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The name it has until then (and keeps if cut).
    pub fn partial(&self) -> &Path {
        &self.partial
    }

    /// Syncs what was written to the disk and gives the file its own name
    /// (then syncs the directory, so the name survives a crash too);
    /// returns that name. Call after the last write, and after flushing any
    /// buffer around it.
    pub fn commit(self) -> Result<PathBuf, DurableError> {
        self.file.sync_all().map_err(|source| DurableError::Write { path: self.partial.clone(), source })?;
        std::fs::rename(&self.partial, &self.path)
            .map_err(|source| DurableError::Rename { from: self.partial.clone(), to: self.path.clone(), source })?;
        // The rename is in the directory: without its sync a crash could
        // bring back the old name. A directory that cannot be opened or
        // synced (some file systems refuse) does not make the file cut.
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(self.path)
    }
}

impl Write for PartialFile {
    #[inline]
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file.write(buf)
    }

    #[inline]
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.file.write_all(buf)
    }

    #[inline]
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// Writes `bytes` as the whole of `path`: to `path.partial`, synced, then
/// renamed. A failure leaves `path.partial` (cut) and no `path`.
pub fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), DurableError> {
    let mut f = PartialFile::create(path)?;
    f.write_all(bytes).map_err(|source| DurableError::Write { path: f.partial.clone(), source })?;
    f.commit().map(|_| ())
}

/// The cut files under `dir` (and its subdirectories, such as a run's
/// `stream-K/`): every `NAME.partial`, as it is on disk, sorted. A
/// directory that cannot be read is an error naming it.
pub fn cut_files(dir: &Path) -> io::Result<Vec<PathBuf>> {
    cut_files_to(dir, usize::MAX)
}

/// The cut files in `dir` and its subdirectories down to `depth` (0: `dir`
/// alone). Symbolic links are not followed: a run's directory holds its
/// own files only.
pub fn cut_files_to(dir: &Path, depth: usize) -> io::Result<Vec<PathBuf>> {
    let named = |d: &Path, e: io::Error| io::Error::new(e.kind(), format!("reading {}: {e}", d.display()));
    let mut found = Vec::new();
    let mut dirs = vec![(dir.to_path_buf(), 0)];
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

/// Whether `path` is a file still being written, or cut (`NAME.partial`).
pub fn is_partial(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.len() > PARTIAL_SUFFIX.len() && n.ends_with(PARTIAL_SUFFIX))
}

/// The name a cut file would have had: `NAME` for `NAME.partial`.
pub fn whole_name(partial: &Path) -> Option<PathBuf> {
    let name = partial.file_name()?.to_str()?.strip_suffix(PARTIAL_SUFFIX)?;
    (!name.is_empty()).then(|| partial.with_file_name(name))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::dir;

    #[test]
    fn a_file_is_partial_until_committed_then_whole_under_its_name() {
        let d = dir("commit");
        let path = d.join("trace.csv");
        let mut f = PartialFile::create(&path).unwrap();
        f.write_all(b"a,b\n1,2\n").unwrap();
        assert!(!path.exists(), "not whole before the commit");
        assert_eq!(std::fs::read(d.join("trace.csv.partial")).unwrap(), b"a,b\n1,2\n");
        assert_eq!(cut_files(&d).unwrap(), vec![d.join("trace.csv.partial")]);
        assert_eq!(f.commit().unwrap(), path);
        assert_eq!(std::fs::read(&path).unwrap(), b"a,b\n1,2\n");
        assert!(!d.join("trace.csv.partial").exists());
        assert!(cut_files(&d).unwrap().is_empty());
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_dropped_file_stays_cut_and_a_stale_whole_one_goes() {
        let d = dir("drop");
        std::fs::create_dir_all(d.join("stream-1")).unwrap();
        let path = d.join("stream-1").join("received.csv");
        std::fs::write(&path, b"an earlier run's\n").unwrap();
        {
            let mut f = PartialFile::create(&path).unwrap();
            f.write_all(b"ingress_index\n0").unwrap();
        }
        assert!(!path.exists(), "an earlier run's whole file does not stand beside a cut one");
        write_whole(&d.join("report.json"), b"{}").unwrap();
        let cut = cut_files(&d).unwrap();
        assert_eq!(cut, vec![d.join("stream-1").join("received.csv.partial")]);
        assert_eq!(whole_name(&cut[0]), Some(path));
        assert_eq!(std::fs::read(d.join("report.json")).unwrap(), b"{}");
        assert!(!is_partial(Path::new(".partial")) && is_partial(Path::new("x.partial")));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn errors_name_the_file() {
        let e = write_whole(Path::new("/nonexistent-netfi-dir/report.json"), b"{}").unwrap_err();
        assert!(e.to_string().contains("/nonexistent-netfi-dir/report.json.partial"), "{e}");
        let e = cut_files(Path::new("/nonexistent-netfi-dir")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent-netfi-dir"), "{e}");
    }
}
