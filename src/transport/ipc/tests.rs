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
