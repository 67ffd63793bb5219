//! This user's iceoryx2 root directory and file prefix: private, resolved
//! once per process, agreed on by every process of a run.

use crate::host::private_dir::{self, PrivateDir, PrivateDirError};
use iceoryx2::prelude::SemanticString;
use std::path::{Path, PathBuf};

/// Prefix of every iceoryx2 file of netfi; `u<uid>_`, the run id and `_`
/// follow.
pub(super) const FILE_PREFIX: &str = "netfi_";

/// This user's file prefix: `netfi_u<uid>_`.
pub(super) fn user_prefix() -> String {
    // SAFETY: geteuid has no preconditions.
    format!("{FILE_PREFIX}u{}_", unsafe { libc::geteuid() })
}

/// The environment variable through which a process tells the processes
/// it starts which iceoryx2 root directory the run uses, so that all of a
/// run's processes agree on it even where the usual one was taken.
pub const IPC_ROOT_ENV: &str = "NETFI_IPC_ROOT";

/// The longest root directory accepted, in bytes: iceoryx2's paths (root,
/// sub-directory, prefix, run id and its own names) must stay within its
/// path limit.
const ROOT_MAX_LEN: usize = 96;

/// This user's iceoryx2 root directory, with a trailing `/` (see
/// [`user_root_dir_resolved`]); where none can be had, the usual name,
/// which opening a node then reports.
pub fn user_root_dir() -> PathBuf {
    let dir = ensure_user_root_dir().unwrap_or_else(|_| usual_root_dirs().pop().unwrap_or_default());
    let mut text = dir.into_os_string();
    text.push("/");
    text.into()
}

/// This user's iceoryx2 root directory, private (0700, this user's, closed
/// to others), created if missing, chosen in this order:
///
/// 1. [`IPC_ROOT_ENV`], as set by the process that started this one;
/// 2. `$XDG_RUNTIME_DIR/netfi-iceoryx2`, where `$XDG_RUNTIME_DIR` is a
///    private directory of this user;
/// 3. `/tmp/netfi-iceoryx2-<uid>`;
/// 4. where those are taken by someone else (another owner, or open to
///    others): the first `/tmp/netfi-iceoryx2-<uid>-XXXXXX` of this user,
///    made if none exists, with a warning naming the owner of the taken
///    one.
pub fn user_root_dir_resolved() -> Result<PrivateDir, PrivateDirError> {
    let named = std::env::var_os(IPC_ROOT_ENV).filter(|e| !e.is_empty()).map(PathBuf::from).filter(|p| usable_root(p));
    private_dir::resolve_named(named, &usual_root_dirs(), Path::new("/tmp"), &format!("netfi-iceoryx2-{}", private_dir::uid()))
}

/// The usual places of the root that iceoryx2 can use, in order of
/// preference.
fn usual_root_dirs() -> Vec<PathBuf> {
    let tmp = PathBuf::from(format!("/tmp/netfi-iceoryx2-{}", private_dir::uid()));
    private_dir::xdg_runtime_dir().map(|d| d.join("netfi-iceoryx2")).into_iter().chain([tmp]).filter(|p| usable_root(p)).collect()
}

/// Whether iceoryx2 can have its files under `dir`.
fn usable_root(dir: &Path) -> bool {
    dir.is_absolute() && dir.as_os_str().len() <= ROOT_MAX_LEN && iceoryx2::prelude::Path::new(dir.as_os_str().as_encoded_bytes()).is_ok()
}

/// The root this process resolved, while it stays private.
static ROOT: std::sync::Mutex<Option<PathBuf>> = std::sync::Mutex::new(None);

/// This user's root directory, resolved once per process (again only if it
/// was removed meanwhile); a taken usual name is warned of once.
pub(super) fn ensure_user_root_dir() -> Result<PathBuf, PrivateDirError> {
    let mut root = ROOT.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(dir) = root.as_ref().filter(|d| private_dir::is_private(d)) {
        return Ok(dir.clone());
    }
    let dir = user_root_dir_resolved()?;
    if let Some(w) = dir.warning() {
        eprintln!("WARNING: iceoryx2's directory: {w}");
    }
    *root = Some(dir.path.clone());
    Ok(dir.path)
}
