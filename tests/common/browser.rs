//! Headless chromium for the tests that drive pages as a user would.

use headless_chrome::{Browser, LaunchOptions};
use std::path::PathBuf;
use std::time::Duration;

/// `NETFI_CHROMIUM`, else the first chromium or Chrome on `PATH`.
fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("NETFI_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"]
        .iter()
        .flat_map(|name| std::env::split_paths(&path).map(move |d| d.join(name)))
        .find(|p| p.is_file())
}

/// Headless chromium, 1280 pixels wide and `height` high, with `extra`
/// command-line switches; `None` where there is none, said on stderr for
/// `what` (where `NETFI_REQUIRE_BROWSER` is set, that fails the test).
pub fn launch_or_skip(what: &str, height: u32, extra: &[&str]) -> Option<Browser> {
    let Some(path) = chromium() else {
        assert!(std::env::var_os("NETFI_REQUIRE_BROWSER").is_none(), "NETFI_REQUIRE_BROWSER is set but no chromium was found");
        eprintln!("SKIP: no chromium on PATH (set NETFI_CHROMIUM): {what} did not run");
        return None;
    };
    let opts = LaunchOptions::default_builder()
        .path(Some(path))
        .headless(true)
        // Root in a container has no user namespace for the sandbox.
        .sandbox(false)
        .window_size(Some((1280, height)))
        // Nothing of the browser's in /dev/shm: a test leaves the host as it found it.
        .args(std::iter::once("--disable-dev-shm-usage").chain(extra.iter().copied()).map(std::ffi::OsStr::new).collect())
        .idle_browser_timeout(Duration::from_secs(300))
        .build()
        .expect("launch options");
    Some(Browser::new(opts).expect("starting chromium"))
}
