//! Unit tests' scratch directories: one fresh, empty directory per test
//! under the system's temporary directory, named by the test's module and
//! this process, so tests running at once never share one.

use std::path::PathBuf;

/// `$TMPDIR/netfi-<label>-<pid>-<name>`, emptied and created.
pub(crate) fn dir(label: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-{label}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
