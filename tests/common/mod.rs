//! What the modules of the `all` test binary share.

pub mod browser;
pub mod heap_queue;
pub mod machine;
pub mod netfi;
pub mod netns;
pub mod scratch;

/// The name libtest knows the test `name` of module `module` (its
/// `module_path!()`) by, for a test that runs one test of this binary in a
/// child process.
pub fn test_name(module: &str, name: &str) -> String {
    let (_crate, path) = module.split_once("::").expect("a module of the test binary");
    format!("{path}::{name}")
}

/// The shipped console recording (`../shared/data`, beside the checkout),
/// or `None` where it is absent: the caller's test says so and passes.
pub fn shipped_capture() -> Option<std::path::PathBuf> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/itp/dvtrainer_peg_transfer.bin");
    if path.is_file() {
        Some(path)
    } else {
        eprintln!("skipping: the shipped capture {} is absent", path.display());
        None
    }
}
