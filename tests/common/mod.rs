//! What the modules of the `all` test binary share.

pub mod browser;
pub mod data;
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

/// Waits (up to a minute) for `path` to appear: a process saying it is ready.
#[track_caller]
pub fn wait_file(path: &std::path::Path) {
    let t0 = std::time::Instant::now();
    while !path.exists() {
        assert!(t0.elapsed() < std::time::Duration::from_secs(60), "{} never appeared", path.display());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// `report` (a run's or an emulator's) of PLM-2 with seed 3 over 20 000
/// frames: the model's loss rate inside the report's 95 % interval, and
/// the very drops `netfi scenario check` gives that seed in simulated time.
#[track_caller]
pub fn assert_plm2_seed3_is_the_checks(report: &serde_json::Value) {
    use self::netfi::Outcome;
    let exact = report["stages"][0]["loss_rate_model"].as_f64().unwrap();
    let [lo, hi] = [report["loss_rate_ci95"][0].as_f64().unwrap(), report["loss_rate_ci95"][1].as_f64().unwrap()];
    assert!(lo <= exact && exact <= hi, "model {exact} outside [{lo}, {hi}]");
    let check = self::netfi::netfi().args(["scenario", "check", "PLM-2", "--frames", "20000", "--seed", "3", "--json"]).json();
    assert_eq!(check["dropped"]["ge_lomax"], report["frames"]["dropped"]["ge_lomax"]);
}
