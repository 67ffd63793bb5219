//! Unit tests' scratch directories: one fresh, empty directory per test
//! under the system's temporary directory, named by the calling file, the
//! test's name and this process, so tests running at once never share one.

use std::path::PathBuf;

/// `$TMPDIR/netfi-<file>-<pid>-<name>`, emptied and created; `<file>` is
/// the caller's source file (`src/load.rs` gives `load`).
#[track_caller]
pub(crate) fn dir(name: &str) -> PathBuf {
    let file = std::panic::Location::caller().file();
    let label = file.trim_start_matches("src/").trim_end_matches(".rs").replace('/', "-");
    let d = std::env::temp_dir().join(format!("netfi-{label}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
