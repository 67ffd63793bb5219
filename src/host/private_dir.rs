//! A directory of this user's that nobody else can enter, in places others
//! may write to (`/tmp`). A name there can be taken first by anyone: a
//! directory found under the expected name that is not this user's, or
//! open to others, is passed over (and named, with its owner) for one
//! made fresh by `mkdtemp` beside it, `<stem>-XXXXXX`, which later
//! processes of the same user find again by its stem. A leaf: it knows
//! nothing of netfi.
//!
//! Processes that must agree on one directory (the processes of one run)
//! should be told it by the one that resolved it: two that both find the
//! expected name taken, at the same moment, may each make a fresh one.

use std::fmt;
use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

/// A directory under an expected name that was not used: not this user's,
/// not a directory, or open to others.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Squatted {
    pub path: PathBuf,
    /// Its owner.
    pub uid: u32,
    /// Its permission bits.
    pub mode: u32,
    /// Whether it is a directory at all (not a file or a symbolic link).
    pub is_dir: bool,
}

impl fmt::Display for Squatted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.is_dir { "a directory" } else { "not a directory" };
        write!(f, "{} ({what}) belongs to uid {}, mode {:o}", self.path.display(), self.uid, self.mode)
    }
}

/// The directory chosen, and what was passed over on the way.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrivateDir {
    pub path: PathBuf,
    /// Expected directories that could not be used, in the order tried.
    pub passed_over: Vec<Squatted>,
}

impl PrivateDir {
    /// What a user must be told when an expected directory was passed
    /// over: whose it is, and where this user's files go instead.
    pub fn warning(&self) -> Option<String> {
        if self.passed_over.is_empty() {
            return None;
        }
        let taken: Vec<String> = self.passed_over.iter().map(Squatted::to_string).collect();
        Some(format!(
            "{}: not a private directory of uid {}; using {} instead (remove it to have the usual name back)",
            taken.join("; "),
            uid(),
            self.path.display()
        ))
    }
}

/// Why no private directory could be had.
#[derive(Debug, thiserror::Error)]
pub enum PrivateDirError {
    /// Creating a directory failed for a reason other than its name being
    /// taken.
    #[error("creating {}: {source}", path.display())]
    Create {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// This process's effective uid.
pub fn uid() -> u32 {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() }
}

/// `$XDG_RUNTIME_DIR` when it names a private directory of this user (as
/// the login manager makes it); `None` otherwise, for instance when it was
/// inherited from another user through `sudo`.
pub fn xdg_runtime_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty())?);
    (dir.is_absolute() && is_private(&dir)).then_some(dir)
}

/// Whether `path` is a directory (not a link) of this user closed to others.
pub fn is_private(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir() && m.uid() == uid() && m.mode() & 0o077 == 0)
}

/// The first of `preferred` that is, or is now created as, a private
/// directory of this user; where each is taken, the first private
/// `<stem>-*` directory of this user in `parent` (by name), else a new one
/// there. A preferred directory whose parent does not exist is skipped
/// silently (not taken, only absent).
pub fn resolve(preferred: &[PathBuf], parent: &Path, stem: &str) -> Result<PrivateDir, PrivateDirError> {
    let mut passed_over = Vec::new();
    for path in preferred {
        match std::fs::DirBuilder::new().mode(0o700).create(path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(source) => return Err(PrivateDirError::Create { path: path.clone(), source }),
        }
        if is_private(path) {
            return Ok(PrivateDir { path: path.clone(), passed_over });
        }
        if let Ok(m) = std::fs::symlink_metadata(path) {
            passed_over.push(Squatted { path: path.clone(), uid: m.uid(), mode: m.mode() & 0o7777, is_dir: m.is_dir() });
        }
    }
    let path = match found_again(parent, stem) {
        Some(p) => p,
        None => make_fresh(parent, stem)?,
    };
    Ok(PrivateDir { path, passed_over })
}

/// [`resolve`], but `named` first, taken as it is when it is a private
/// directory of this user (a directory a parent process resolved and named
/// to its children), passed over otherwise.
pub fn resolve_named(named: Option<PathBuf>, preferred: &[PathBuf], parent: &Path, stem: &str) -> Result<PrivateDir, PrivateDirError> {
    let mut passed_over = Vec::new();
    if let Some(dir) = named {
        if is_private(&dir) {
            return Ok(PrivateDir { path: dir, passed_over });
        }
        let m = std::fs::symlink_metadata(&dir).ok();
        passed_over.push(Squatted {
            uid: m.as_ref().map_or(uid(), MetadataExt::uid),
            mode: m.as_ref().map_or(0, |m| m.mode() & 0o7777),
            is_dir: m.is_some_and(|m| m.is_dir()),
            path: dir,
        });
    }
    let mut dir = resolve(preferred, parent, stem)?;
    passed_over.append(&mut dir.passed_over);
    dir.passed_over = passed_over;
    Ok(dir)
}

/// The first private directory of this user named `<stem>-*` in `parent`.
fn found_again(parent: &Path, stem: &str) -> Option<PathBuf> {
    let want = format!("{stem}-");
    let mut mine: Vec<PathBuf> = std::fs::read_dir(parent)
        .ok()?
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_str().is_some_and(|n| n.starts_with(&want)))
        .map(|e| e.path())
        .filter(|p| is_private(p))
        .collect();
    mine.sort();
    mine.into_iter().next()
}

/// A new directory `<parent>/<stem>-XXXXXX`, mode 0700 (`mkdtemp`).
fn make_fresh(parent: &Path, stem: &str) -> Result<PathBuf, PrivateDirError> {
    use std::os::unix::ffi::OsStringExt;
    let template = parent.join(format!("{stem}-XXXXXX"));
    let error = |source| PrivateDirError::Create { path: template.clone(), source };
    let mut bytes = template.clone().into_os_string().into_vec();
    if bytes.contains(&0) {
        return Err(error(std::io::Error::from(std::io::ErrorKind::InvalidInput)));
    }
    bytes.push(0);
    // SAFETY: `bytes` is a NUL-terminated, writable template ending in
    // XXXXXX, which mkdtemp overwrites in place.
    if unsafe { libc::mkdtemp(bytes.as_mut_ptr().cast()) }.is_null() {
        return Err(error(std::io::Error::last_os_error()));
    }
    bytes.pop();
    Ok(PathBuf::from(std::ffi::OsString::from_vec(bytes)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;
    use crate::scratch::dir as scratch;

    #[test]
    fn the_expected_directory_is_created_private() {
        let base = scratch("fresh");
        let want = base.join("netfi-1");
        let got = resolve(std::slice::from_ref(&want), &base, "netfi-1").unwrap();
        assert_eq!(got, PrivateDir { path: want.clone(), passed_over: vec![] });
        assert!(is_private(&want));
        assert_eq!(got.warning(), None);
        std::fs::remove_dir_all(&base).unwrap();
    }

    /// A directory open to others (or, as root, another user's) under the
    /// expected name is named and passed over; later calls find the same
    /// replacement.
    #[test]
    fn a_taken_directory_is_passed_over_and_its_replacement_found_again() {
        let base = scratch("taken");
        let want = base.join("netfi-1");
        std::fs::create_dir(&want).unwrap();
        std::fs::set_permissions(&want, std::fs::Permissions::from_mode(0o777)).unwrap();
        let squatter = if uid() == 0 { 12345 } else { uid() };
        if uid() == 0 {
            std::os::unix::fs::chown(&want, Some(squatter), Some(squatter)).unwrap();
        }
        let first = resolve(std::slice::from_ref(&want), &base, "netfi-1").unwrap();
        assert_ne!(first.path, want);
        assert!(first.path.file_name().unwrap().to_str().unwrap().starts_with("netfi-1-"), "{first:?}");
        assert!(is_private(&first.path));
        assert_eq!(first.passed_over, vec![Squatted { path: want.clone(), uid: squatter, mode: 0o777, is_dir: true }]);
        let warning = first.warning().unwrap();
        assert!(warning.contains(&format!("belongs to uid {squatter}")) && warning.contains(&first.path.display().to_string()), "{warning}");
        let again = resolve(std::slice::from_ref(&want), &base, "netfi-1").unwrap();
        assert_eq!(again.path, first.path);
        // A look-alike of another user's, or open to others, is never taken.
        std::fs::set_permissions(&first.path, std::fs::Permissions::from_mode(0o755)).unwrap();
        let third = resolve(std::slice::from_ref(&want), &base, "netfi-1").unwrap();
        assert_ne!(third.path, first.path);
        std::fs::remove_dir_all(&base).unwrap();
    }

    /// The directory a parent named is taken as it is; one that is not a
    /// private directory of this user is passed over, and said.
    #[test]
    fn a_named_directory_is_taken_only_when_private() {
        let base = scratch("named");
        let (named, usual) = (base.join("named"), base.join("netfi-1"));
        std::fs::create_dir(&named).unwrap();
        std::fs::set_permissions(&named, std::fs::Permissions::from_mode(0o700)).unwrap();
        let got = resolve_named(Some(named.clone()), std::slice::from_ref(&usual), &base, "netfi-1").unwrap();
        assert_eq!(got, PrivateDir { path: named.clone(), passed_over: vec![] });
        std::fs::set_permissions(&named, std::fs::Permissions::from_mode(0o755)).unwrap();
        let got = resolve_named(Some(named.clone()), std::slice::from_ref(&usual), &base, "netfi-1").unwrap();
        assert_eq!(got.path, usual);
        assert_eq!(got.passed_over, vec![Squatted { path: named, uid: uid(), mode: 0o755, is_dir: true }]);
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn a_file_or_a_link_under_the_name_is_passed_over() {
        let base = scratch("link");
        let want = base.join("netfi-1");
        std::os::unix::fs::symlink(&base, &want).unwrap();
        let got = resolve(std::slice::from_ref(&want), &base, "netfi-1").unwrap();
        assert!(!got.passed_over[0].is_dir);
        assert_ne!(got.path, want);
        // A preferred place whose parent is absent is skipped without a word.
        let absent = base.join("no/such/dir");
        let got = resolve(&[absent, base.join("netfi-2")], &base, "netfi-2").unwrap();
        assert_eq!(got.path, base.join("netfi-2"));
        assert!(got.passed_over.is_empty());
        std::fs::remove_dir_all(&base).unwrap();
    }
}
