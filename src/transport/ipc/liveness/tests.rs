use super::*;

#[test]
fn monitor_file_names_yield_their_run() {
    let suffix = ".node_monitor";
    let p = user_prefix();
    let run = |n: &str| run_of_monitor_file(&n.replacen("netfi_", &p, 1), suffix).map(|r| r.as_str().to_owned());
    assert_eq!(run("netfi_r1_123.node_monitor").as_deref(), Some("r1"));
    assert_eq!(run("netfi_a_b-c_9.node_monitor").as_deref(), Some("a_b-c"));
    assert_eq!(run("netfi__9.node_monitor"), None);
    assert_eq!(run("netfi_r1_12x.node_monitor"), None);
    assert_eq!(run("netfi_r1_.node_monitor"), None);
    assert_eq!(run("iox2_123.node_monitor"), None);
    // Another user's files are not this user's runs.
    assert_eq!(run_of_monitor_file("netfi_u4294967294_r1_1.node_monitor", suffix), None);
    assert_eq!(run("netfi_r1_123.details"), None);
}

/// A run's files are told from those of a run whose id extends it.
#[test]
fn file_names_yield_their_run_exactly() {
    let p = user_prefix();
    let hash = "0123456789abcdef0123456789abcdef01234567";
    let run = |n: String| run_of_file(&n).map(|r| r.as_str().to_owned());
    assert_eq!(run(format!("{p}a_{hash}_15.data")).as_deref(), Some("a"));
    assert_eq!(run(format!("{p}a_b_{hash}_15.data")).as_deref(), Some("a_b"));
    assert_eq!(run(format!("{p}a_b_{hash}.service")).as_deref(), Some("a_b"));
    assert_eq!(run(format!("{p}a_12_34.node_monitor_context")).as_deref(), Some("a_12"));
    assert_eq!(run(format!("{p}r-1_node.details")).as_deref(), Some("r-1"));
    assert_eq!(run(format!("{p}r1_whatever")), None);
    assert_eq!(run(format!("netfi_u4294967294_r1_{hash}_1.data")), None);
    // Run `a` does not claim the files of run `a_b`.
    assert!(!owned_member(std::path::Path::new(&format!("/nonexistent/{p}a_b_{hash}_1.data")), &format!("{p}a_")));
}
