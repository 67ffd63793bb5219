//! What the modules of the `all` test binary share.

pub mod heap_queue;
pub mod machine;
pub mod netfi;
pub mod netns;

/// The name libtest knows the test `name` of module `module` (its
/// `module_path!()`) by, for a test that runs one test of this binary in a
/// child process.
pub fn test_name(module: &str, name: &str) -> String {
    let (_crate, path) = module.split_once("::").expect("a module of the test binary");
    format!("{path}::{name}")
}
