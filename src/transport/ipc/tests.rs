use super::*;
use crate::host::private_dir;

#[test]
fn run_id_accepts_the_documented_alphabet() {
    for ok in ["a", "run-1", "R_2024-05-01", &"x".repeat(RunId::MAX_LEN)] {
        assert_eq!(RunId::new(ok).unwrap().as_str(), ok);
    }
}

#[test]
fn run_id_rejects_the_rest() {
    assert_eq!(RunId::new(""), Err(RunIdError::Empty));
    assert!(matches!(
        RunId::new(&"x".repeat(RunId::MAX_LEN + 1)),
        Err(RunIdError::TooLong { len: 49, .. })
    ));
    for (bad, ch, index) in [
        ("a/b", '/', 1),
        ("a b", ' ', 1),
        (".", '.', 0),
        ("é", 'é', 0),
    ] {
        assert_eq!(
            RunId::new(bad),
            Err(RunIdError::InvalidCharacter {
                run: bad.to_owned(),
                ch,
                index
            })
        );
    }
}

#[test]
fn config_is_explicit_and_prefixed_per_run() {
    let config = IpcConfig::new(RunId::new("r1").unwrap());
    let uid = unsafe { libc::geteuid() };
    assert_eq!(config.prefix(), format!("netfi_u{uid}_r1_"));
    let root = user_root_dir();
    assert_eq!(config.iceoryx2().global.root_path().to_string(), root.to_string_lossy());
    assert!(private_dir::is_private(&root));
    assert_eq!(config.service_name(Port::CONSOLE), "netfi/r1/console");
    assert_eq!(config.node_name(Role::Simulator), "netfi/r1/simulator");
    assert_eq!(
        config.role_of_node_name("netfi/r1/emulator"),
        Some(Role::Emulator)
    );
    assert_eq!(config.role_of_node_name("netfi/r2/emulator"), None);
    let iox = config.iceoryx2();
    assert!(!iox.defaults.publish_subscribe.enable_safe_overflow);
    assert_eq!(
        iox.defaults.publish_subscribe.subscriber_max_buffer_size,
        SUBSCRIBER_BUFFER_FRAMES
    );
    assert!(!iox.global.node.cleanup_dead_nodes_on_creation);
}

#[test]
fn log_level_parses() {
    assert_eq!("WARN".parse::<IpcLogLevel>(), Ok(IpcLogLevel::Warn));
    assert!("loud".parse::<IpcLogLevel>().is_err());
}

/// netfi makes the run's management segment, private, before iceoryx2
/// would make its own open to all: iceoryx2 takes netfi's (it numbers its
/// nodes in it), so the segment never had any mode but the owner's. Fails
/// on an iceoryx2 that names or lays the segment out otherwise.
#[test]
fn iceoryx2_takes_the_management_segment_netfi_made_private() {
    use std::os::unix::fs::MetadataExt;
    let run = RunId::new(&format!("mgmt{}", std::process::id())).unwrap();
    let config = IpcConfig::new(run);
    let path = mgmt_segment_path(config.prefix());
    let _ = std::fs::remove_file(&path);
    let counter = || std::fs::read(&path).ok().filter(|b| b.len() >= 12).map(|b| u32::from_ne_bytes(b[8..12].try_into().unwrap()));
    let node = IpcNode::open(&config, Role::Console).unwrap();
    let mode = std::fs::metadata(&path).map(|m| m.mode() & 0o777);
    let first = counter();
    let second_node = IpcNode::open(&config, Role::Simulator).unwrap();
    let second = counter();
    drop(second_node);
    drop(node);
    let _ = std::fs::remove_file(&path);
    assert_eq!(mode.ok(), Some(0o600), "{} is not the segment iceoryx2 took, or not private", path.display());
    assert_eq!((first, second), (Some(1), Some(2)), "iceoryx2 did not number its nodes in netfi's segment");
}
