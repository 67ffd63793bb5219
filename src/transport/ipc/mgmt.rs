//! The run's management segment, private from its first instant.
//!
//! iceoryx2 keeps one management segment per file prefix (a counter that
//! numbers the nodes), shared by the run's processes. Where it creates the
//! segment itself it opens it to every user: after writing it, it sets the
//! mode to 0666 with `fchmod` (`enable_global_access`), which no umask
//! narrows, and netfi's own chmod ([`super::node`]'s `make_private`) comes
//! only once the node is open. Another user polling `/dev/shm` could open
//! the segment read-write in between and keep the handle.
//!
//! So a process about to open the run's first node creates the segment
//! itself, the way iceoryx2 does (write-only while being written, which
//! iceoryx2 reads as "not yet initialized"; then its version and a zero
//! counter; then readable), but 0600 throughout. iceoryx2 then finds it,
//! checks its version, and uses it: it never creates its own. Should
//! iceoryx2 name or lay out the segment otherwise (another version), it
//! ignores this one, makes its own, and netfi's chmod stays the second
//! line; `iceoryx2_takes_the_management_segment_netfi_made_private` (the
//! unit tests) fails on such a version.

use iceoryx2_bb_elementary::package_version::PackageVersion;
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::PathBuf;

use super::liveness::SHM_DIR;

/// iceoryx2's type hash of the segment's payload: the SHA-1, in hex, of
/// its type's name, `iceoryx2::node::global_management_segment::State`.
const STATE_TYPE_HASH: &str = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5";

/// iceoryx2's name of the segment (`GLOBAL_MGMT_NAME`).
const MGMT_NAME: &str = "node";

/// The segment's bytes (iceoryx2's `Data<State>`, `repr(C)`): the package
/// version as a `u64`, the node counter as a `u32`, padding to 8 bytes.
const MGMT_LEN: usize = 16;

/// The path of the management segment of the file prefix `prefix`, as
/// iceoryx2 names it: prefix, type hash, `_node`, `.MAJOR_MINOR_PATCH`,
/// `.global_mgmt`.
pub fn mgmt_segment_path(prefix: &str) -> PathBuf {
    let v = PackageVersion::get();
    PathBuf::from(SHM_DIR).join(format!("{prefix}{STATE_TYPE_HASH}_{MGMT_NAME}.{}_{}_{}.global_mgmt", v.major(), v.minor(), v.patch()))
}

/// Creates the management segment of `prefix` private (see the module
/// docs), unless something is at its name already (this run's, made by a
/// process before; another user's, refused where the node is opened).
/// Best effort: a segment that cannot be made whole is removed, and
/// iceoryx2 makes its own.
pub(super) fn create_private(prefix: &str) {
    let path = mgmt_segment_path(prefix);
    // Write-only until whole: iceoryx2 waits on a segment its owner cannot
    // read yet, as on one it is writing itself.
    let Ok(mut f) = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o200)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&path)
    else {
        return;
    };
    let mut bytes = [0u8; MGMT_LEN];
    bytes[..8].copy_from_slice(&PackageVersion::get().to_u64().to_ne_bytes());
    let made = std::io::Write::write_all(&mut f, &bytes).and_then(|_| f.set_permissions(std::fs::Permissions::from_mode(0o600)));
    if made.is_err() {
        let _ = std::fs::remove_file(&path);
    }
}
