//! Files that are whole or say they are cut, written only where they are
//! meant to be.
//!
//! A run's files (its traces, `received.csv`, `video_received.csv`, the
//! histogram logs, its JSON reports, the processes' logs) are written
//! under a temporary name, `NAME.partial`, and renamed to `NAME` only once
//! every byte is written, flushed and synced to the disk. So:
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
//! No symbolic link is ever followed to a file: the directory is opened
//! without following a link at its own name ([`Dir`]), and every file in
//! it is created (`O_CREAT | O_EXCL | O_NOFOLLOW`), renamed and removed
//! relative to it. A link planted at a file's name is removed, never
//! written through; a directory that is itself a link is refused.
//!
//! [`PartialFile`] streams a file this way ([`PartialFile::commit`] ends
//! it); [`write_whole`] writes one in a single call (a JSON report).

use std::ffi::{CString, OsStr, OsString};
use std::fs::File;
use std::io::{self, Write};
use std::os::fd::{AsRawFd, FromRawFd};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// The suffix of a file still being written, or cut.
pub const PARTIAL_SUFFIX: &str = ".partial";

/// The mode a run's files are created with, before the umask: as
/// `File::create`.
pub const FILE_MODE: u32 = 0o666;

/// A directory opened once, without following a symbolic link at its own
/// name (`O_DIRECTORY | O_NOFOLLOW`), in which files are then created,
/// renamed and removed by name relative to it (`openat`, `renameat`,
/// `unlinkat`): what is written lands in this directory, whatever is
/// later planted at its path or at a file's name.
#[derive(Debug)]
pub struct Dir {
    fd: File,
    path: PathBuf,
}

impl Dir {
    /// Opens `path` (`""` is the current directory). A symbolic link there
    /// is an error saying so; the directories above it are followed as
    /// usual.
    pub fn open(path: &Path) -> io::Result<Dir> {
        let at = if path.as_os_str().is_empty() { Path::new(".") } else { path };
        let fd = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(at)
            .map_err(|e| match e.raw_os_error() {
                Some(libc::ELOOP | libc::ENOTDIR) if at.symlink_metadata().is_ok_and(|m| m.file_type().is_symlink()) => io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("{} is a symbolic link: netfi writes into a directory only by its own name (give the directory the link points to)", at.display()),
                ),
                _ => e,
            })?;
        Ok(Dir { fd, path: path.to_path_buf() })
    }

    /// The directory of `path` and the file's name in it.
    pub fn of(path: &Path) -> io::Result<(Dir, OsString)> {
        let name = path.file_name().ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, format!("{}: not a file's name", path.display())))?;
        Ok((Dir::open(path.parent().unwrap_or(Path::new("")))?, name.to_os_string()))
    }

    /// The directory's path, as it was opened.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The path of `name` in the directory.
    pub fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.path.join(name)
    }

    /// The directory's owner, mode and kind (of what was opened, not of
    /// what its path names now).
    pub fn metadata(&self) -> io::Result<std::fs::Metadata> {
        self.fd.metadata()
    }

    /// Creates `name` anew for writing, with `mode` (less the umask): an
    /// error if anything (a file, a symbolic link) is there already.
    pub fn create_new(&self, name: &OsStr, mode: u32) -> io::Result<File> {
        self.open_at(name, libc::O_WRONLY | libc::O_CREAT | libc::O_EXCL, mode)
    }

    /// Opens `name` for reading and writing, created with `mode` if
    /// missing, never truncated (a lock file): a symbolic link there is an
    /// error saying so.
    pub fn open_or_create(&self, name: &OsStr, mode: u32) -> io::Result<File> {
        self.open_at(name, libc::O_RDWR | libc::O_CREAT, mode).map_err(|e| self.no_link(name, e))
    }

    /// Opens `name` for reading, refusing a symbolic link.
    pub fn open_read(&self, name: &OsStr) -> io::Result<File> {
        self.open_at(name, libc::O_RDONLY, 0).map_err(|e| self.no_link(name, e))
    }

    fn open_at(&self, name: &OsStr, flags: libc::c_int, mode: u32) -> io::Result<File> {
        let c = c_name(name)?;
        // SAFETY: openat on a directory descriptor this value owns, with a
        // NUL-terminated name; the descriptor returned is owned by the File.
        let fd = unsafe { libc::openat(self.fd.as_raw_fd(), c.as_ptr(), flags | libc::O_NOFOLLOW | libc::O_CLOEXEC, mode as libc::c_uint) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: `fd` was just opened and is owned by nothing else.
        Ok(unsafe { File::from_raw_fd(fd) })
    }

    /// ELOOP on a final component opened with `O_NOFOLLOW` is a link.
    fn no_link(&self, name: &OsStr, e: io::Error) -> io::Error {
        if e.raw_os_error() == Some(libc::ELOOP) {
            return io::Error::new(io::ErrorKind::InvalidInput, format!("{} is a symbolic link (not followed)", self.join(name).display()));
        }
        e
    }

    /// Removes `name` (a file or a symbolic link, never what a link points
    /// to); `false` if nothing was there.
    pub fn remove(&self, name: &OsStr) -> io::Result<bool> {
        let c = c_name(name)?;
        // SAFETY: unlinkat on a directory descriptor this value owns, with a
        // NUL-terminated name.
        if unsafe { libc::unlinkat(self.fd.as_raw_fd(), c.as_ptr(), 0) } == 0 {
            return Ok(true);
        }
        let e = io::Error::last_os_error();
        if e.kind() == io::ErrorKind::NotFound {
            return Ok(false);
        }
        Err(e)
    }

    /// Renames `from` to `to`, both in this directory (a link at `to` is
    /// replaced, not followed).
    pub fn rename(&self, from: &OsStr, to: &OsStr) -> io::Result<()> {
        let (f, t) = (c_name(from)?, c_name(to)?);
        let d = self.fd.as_raw_fd();
        // SAFETY: renameat within a directory descriptor this value owns,
        // with NUL-terminated names.
        if unsafe { libc::renameat(d, f.as_ptr(), d, t.as_ptr()) } == 0 {
            return Ok(());
        }
        Err(io::Error::last_os_error())
    }

    /// What is at `name`, not following a link.
    pub fn entry(&self, name: &OsStr) -> io::Result<Option<libc::stat>> {
        let c = c_name(name)?;
        let mut st = std::mem::MaybeUninit::<libc::stat>::uninit();
        // SAFETY: fstatat on a directory descriptor this value owns, a
        // NUL-terminated name and a buffer of the right size.
        if unsafe { libc::fstatat(self.fd.as_raw_fd(), c.as_ptr(), st.as_mut_ptr(), libc::AT_SYMLINK_NOFOLLOW) } == 0 {
            // SAFETY: fstatat succeeded, so it filled the buffer.
            return Ok(Some(unsafe { st.assume_init() }));
        }
        let e = io::Error::last_os_error();
        if e.kind() == io::ErrorKind::NotFound {
            return Ok(None);
        }
        Err(e)
    }

    /// Syncs the directory (its names), so that a rename survives a crash.
    /// Some file systems refuse: that makes no file cut.
    pub fn sync(&self) {
        let _ = self.fd.sync_all();
    }
}

/// `name` as one component, NUL-terminated.
fn c_name(name: &OsStr) -> io::Result<CString> {
    let bytes = name.as_bytes();
    if bytes.is_empty() || bytes.contains(&b'/') || bytes == b"." || bytes == b".." {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("{}: not a file's name", name.to_string_lossy())));
    }
    CString::new(bytes).map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "a file name with a NUL byte"))
}

/// `NAME.partial` for `NAME`.
fn partial_name(name: &OsStr) -> OsString {
    let mut p = name.to_os_string();
    p.push(PARTIAL_SUFFIX);
    p
}

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

/// Creates `path` anew for a child process's output (a log that another
/// process writes and this one does not see the end of): whatever was at
/// its name, a symbolic link included, removed first, never followed.
pub fn create_fresh(path: &Path) -> io::Result<File> {
    let (dir, name) = Dir::of(path)?;
    dir.remove(&name)?;
    dir.create_new(&name, FILE_MODE)
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
    dir: Dir,
    name: OsString,
    path: PathBuf,
    partial: PathBuf,
}

impl PartialFile {
    /// Creates `path.partial`, after removing a `path` an earlier run left
    /// (and a `path.partial`): whatever was at either name, a symbolic
    /// link included, is removed, not written through.
    pub fn create(path: &Path) -> Result<PartialFile, DurableError> {
        PartialFile::create_mode(path, FILE_MODE)
    }

    /// [`PartialFile::create`] with `mode` (less the umask).
    pub fn create_mode(path: &Path, mode: u32) -> Result<PartialFile, DurableError> {
        let partial = partial_path(path);
        let (dir, name) = Dir::of(path).map_err(|source| DurableError::Create { path: partial.clone(), source })?;
        PartialFile::create_in(dir, &name, mode)
    }

    /// Creates `name.partial` in `dir` (see [`PartialFile::create`]).
    pub fn create_in(dir: Dir, name: &OsStr, mode: u32) -> Result<PartialFile, DurableError> {
        let (path, pname) = (dir.join(name), partial_name(name));
        let partial = dir.join(&pname);
        dir.remove(name).map_err(|source| DurableError::Create { path: path.clone(), source })?;
        dir.remove(&pname).map_err(|source| DurableError::Create { path: partial.clone(), source })?;
        let file = dir.create_new(&pname, mode).map_err(|source| DurableError::Create { path: partial.clone(), source })?;
        Ok(PartialFile { file, dir, name: name.to_os_string(), path, partial })
    }

    /// The name the file has once whole.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The name it has until then (and keeps if cut).
    pub fn partial(&self) -> &Path {
        &self.partial
    }

    /// The file being written (for another process to write to: a child's
    /// log).
    pub fn file(&self) -> &File {
        &self.file
    }

    /// Syncs what was written to the disk and gives the file its own name
    /// (then syncs the directory, so the name survives a crash too);
    /// returns that name. Call after the last write, and after flushing any
    /// buffer around it.
    pub fn commit(self) -> Result<PathBuf, DurableError> {
        self.sync_and_rename()?;
        // The rename is in the directory: without its sync a crash could
        // bring back the old name.
        self.dir.sync();
        Ok(self.path)
    }

    /// [`PartialFile::commit`] but for the directory's sync, left to a
    /// later commit in the same directory (which persists every name in it,
    /// this one's too): a writer of many files in one directory (a lane's
    /// traces, then its report) syncs the directory once. Until then a
    /// crash of the machine may bring back the `.partial` name, never a
    /// whole name over a cut file.
    pub fn commit_unsynced_name(self) -> Result<PathBuf, DurableError> {
        self.sync_and_rename()?;
        Ok(self.path)
    }

    fn sync_and_rename(&self) -> Result<(), DurableError> {
        self.file.sync_all().map_err(|source| DurableError::Write { path: self.partial.clone(), source })?;
        self.dir
            .rename(&partial_name(&self.name), &self.name)
            .map_err(|source| DurableError::Rename { from: self.partial.clone(), to: self.path.clone(), source })
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

impl io::Seek for PartialFile {
    /// A format that writes its index last (MCAP) seeks back.
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

/// Writes `bytes` as the whole of `path`: to `path.partial`, synced, then
/// renamed. A failure leaves `path.partial` (cut) and no `path`.
pub fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), DurableError> {
    write_whole_mode(path, bytes, FILE_MODE)
}

/// [`write_whole`] with `mode` (less the umask).
pub fn write_whole_mode(path: &Path, bytes: &[u8], mode: u32) -> Result<(), DurableError> {
    let mut f = PartialFile::create_mode(path, mode)?;
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
    fn links_planted_at_a_files_names_are_removed_never_followed() {
        let d = dir("links");
        let victim = d.join("victim");
        std::fs::write(&victim, b"secret\n").unwrap();
        for name in ["report.json", "report.json.partial", "console.log", "console.log.partial"] {
            std::os::unix::fs::symlink(&victim, d.join(name)).unwrap();
        }
        write_whole(&d.join("report.json"), b"{}").unwrap();
        let mut log = PartialFile::create(&d.join("console.log")).unwrap();
        log.write_all(b"started\n").unwrap();
        log.commit().unwrap();
        assert_eq!(std::fs::read(&victim).unwrap(), b"secret\n", "a link was written through");
        for name in ["report.json", "console.log"] {
            let m = std::fs::symlink_metadata(d.join(name)).unwrap();
            assert!(m.file_type().is_file(), "{name} is not a file of its own");
        }
        std::os::unix::fs::symlink(&victim, d.join("run.out")).unwrap();
        create_fresh(&d.join("run.out")).unwrap().write_all(b"x").unwrap();
        assert_eq!(std::fs::read(&victim).unwrap(), b"secret\n");
        let lock = Dir::open(&d).unwrap();
        std::os::unix::fs::symlink(&victim, d.join("run.lock")).unwrap();
        let e = lock.open_or_create("run.lock".as_ref(), FILE_MODE).unwrap_err();
        assert!(e.to_string().contains("is a symbolic link"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_directory_that_is_a_link_is_refused() {
        let d = dir("dirlink");
        std::fs::create_dir_all(d.join("real")).unwrap();
        std::os::unix::fs::symlink(d.join("real"), d.join("stream-1")).unwrap();
        let e = write_whole(&d.join("stream-1").join("report.json"), b"{}").unwrap_err();
        assert!(e.to_string().contains("is a symbolic link"), "{e}");
        assert!(std::fs::read_dir(d.join("real")).unwrap().next().is_none(), "written through the link");
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
