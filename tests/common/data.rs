//! The shared data beside the checkout (`../shared/data`): the console
//! recording (`itp/`) and the cellular Mahimahi traces (`traces/`). A test
//! that needs a file of it says so and passes where it is absent, unless
//! `NETFI_REQUIRE_DATA` is set (`.ci/run` sets it: there `../shared` is
//! always beside the checkout), where its absence fails the test.

use std::path::{Path, PathBuf};

/// `../shared/data`, beside the checkout.
pub fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// `relative` under [`dir`] (a file or a folder), or `None` where it is
/// absent, said on stderr for `what`; where `NETFI_REQUIRE_DATA` is set
/// that fails the test instead, naming the path.
#[track_caller]
pub fn or_skip(relative: &str, what: &str) -> Option<PathBuf> {
    let path = dir().join(relative);
    if path.exists() {
        return Some(path);
    }
    assert!(
        std::env::var_os("NETFI_REQUIRE_DATA").is_none(),
        "NETFI_REQUIRE_DATA is set but there is no {} ({what}; the shared data belongs at ../shared/data beside the checkout)",
        path.display()
    );
    eprintln!("skipping: there is no {} ({what})", path.display());
    None
}

/// The shipped console recording, or `None` where it is absent (see
/// [`or_skip`]).
#[track_caller]
pub fn shipped_capture() -> Option<PathBuf> {
    or_skip("itp/dvtrainer_peg_transfer.bin", "the shipped console recording")
}

/// The shared cellular Mahimahi trace `name` (in `traces/`), or `None`
/// where it is absent (see [`or_skip`]).
#[track_caller]
pub fn trace(name: &str) -> Option<PathBuf> {
    or_skip(&format!("traces/{name}"), "a shared Mahimahi trace")
}
