use super::*;
use crate::service::args::tests::{Cli, Cmd};
use clap::Parser;

fn run_args(argv: &[&str]) -> RunArgs {
    match Cli::parse_from([&["netfi", "run"], argv].concat()).cmd {
        Cmd::Run(a) => a,
        _ => unreachable!(),
    }
}

fn normal() -> ScenarioSpec {
    crate::load::resolve("Normal").unwrap()
}

/// What the runner resolves for `args`: its scenario for every stream,
/// Normal for the paths that are on.
fn resolved(args: &RunArgs) -> Resolved {
    let (ends, transports) = (crate::service::args::EndsArgs::default(), crate::transport::TransportArgs::default());
    let shape = crate::service::channel::LaneShape { ingress: &ends.ingress, egress: &ends.egress, transports: &transports, streams: args.stream.streams };
    Resolved { streams: vec![normal(); args.stream.streams as usize], paths: args.channels.wants(&shape).into_iter().map(|(c, w)| (c, w, normal())).collect() }
}

fn plan(argv: &[&str], host: &[usize]) -> Plan {
    let a = run_args(argv);
    Plan::new(&a, &resolved(&a), 7, "r1".into(), host).unwrap()
}

#[test]
fn the_emulator_gets_the_last_core_and_with_four_the_others_get_one_each() {
    assert_eq!(plan(&["Normal"], &[0, 1]).cores, Cores { emulator: Some(1), console: None, simulator: None });
    assert_eq!(plan(&["Normal"], &[0, 1, 2, 3]).cores, Cores { emulator: Some(3), console: Some(1), simulator: Some(2) });
    assert_eq!(plan(&["Normal"], &[0]).cores, Cores { emulator: None, console: None, simulator: None });
    let p = plan(&["Normal", "--emulator-core", "0"], &[0, 1, 2, 3]);
    assert_eq!(p.cores, Cores { emulator: Some(0), console: None, simulator: None });
    let p = plan(&["Normal", "--no-pin"], &[0, 1, 2, 3]);
    assert_eq!(p.cores, Cores { emulator: None, console: None, simulator: None });
    assert!(p.emulator.placement.no_pin && p.streams[0].console.as_ref().unwrap().pin.avoid_core.is_none());
}

#[test]
fn frames_follow_the_duration_the_count_or_the_default() {
    let f = |argv: &[&str]| frames(&run_args(argv)).unwrap();
    assert_eq!(f(&["Normal", "--duration-s", "3"]), (3.0, 3000));
    assert_eq!(f(&["Normal", "--frames", "500", "--rate-hz", "100"]), (5.0, 500));
    assert_eq!(f(&["Normal"]), (10.0, 10_000));
    assert_eq!(f(&["Normal", "--capture", "x.lz4"]), (90.0, 50_000));
}

#[test]
fn a_stream_longer_than_a_week_is_refused_before_anything_starts() {
    let a = run_args(&["Normal", "--frames", "1000000", "--rate-hz", "0.001"]);
    let e = frames(&a).unwrap_err().to_string();
    assert!(e.contains("--frames 1000000 at 0.001 Hz") && e.contains("at most a week (604800 s)"), "{e}");
    assert!(Plan::new(&a, &resolved(&a), 7, "r1".into(), &[0, 1]).is_err());
}

#[test]
fn the_core_is_cleared_unless_asked_not_to_and_only_when_pinned() {
    assert!(plan(&["Normal"], &[0, 1]).emulator.placement.isolate);
    assert!(plan(&["Normal", "--isolate"], &[0, 1]).emulator.placement.isolate);
    assert!(!plan(&["Normal", "--no-isolate"], &[0, 1]).emulator.placement.isolate);
    assert!(plan(&["Normal", "--no-isolate", "--isolate"], &[0, 1]).emulator.placement.isolate, "the later flag wins");
    assert!(plan(&["Normal"], &[0]).emulator.placement.isolate, "no core of its own: passed on, so the report says why nothing was cleared");
}

#[test]
fn each_process_parses_back_what_the_plan_gave_it() {
    let p = plan(&["Normal", "--duration-s", "2", "--rate-hz", "500", "--drop-bad-checksum", "--queue-capacity", "9"], &[0, 1]);
    let parse = |role: &str, argv: Vec<String>| Cli::parse_from([vec!["netfi".to_string(), role.to_string()], argv].concat()).cmd;
    let s0 = &p.streams[0];
    let Cmd::Console(c) = parse("console", s0.console.as_ref().unwrap().to_argv()) else { unreachable!() };
    assert_eq!(c.to_argv(), s0.console.as_ref().unwrap().to_argv());
    assert_eq!((c.source.rate_hz, c.source.duration_s, c.seed, c.pin.avoid_core, c.pin.core), (Some(500.0), Some(2.0), Some(7), Some(1), None));
    let Cmd::Emulator(e) = parse("emulator", p.emulator.to_argv()) else { unreachable!() };
    assert_eq!(e.to_argv(), p.emulator.to_argv());
    assert_eq!((e.placement.core, e.scenario.queue_capacity, e.expected_frames, e.placement.isolate, e.drop_bad_checksum), (Some(1), Some(9), 1000, true, true));
    let Cmd::Simulator(s) = parse("simulator", s0.simulator.as_ref().unwrap().to_argv()) else { unreachable!() };
    assert_eq!(s.to_argv(), s0.simulator.as_ref().unwrap().to_argv());
    assert_eq!((s.pin.avoid_core, s.spin, s.drop_bad_checksum), (Some(1), false, true));
}

#[test]
fn the_emulator_is_told_every_seed_the_runner_decided() {
    let p = plan(&["Normal", "--video-mbps", "2"], &[0, 1]);
    let e = &p.emulator;
    assert_eq!(e.scenario.seed, Some(7));
    assert_eq!(e.channels.feedback.return_seed, Some(seeds::feedback(None, &normal(), 7)));
    assert_eq!(e.channels.video.video_seed, Some(seeds::video(None, &normal(), 7)));
    assert_eq!(e.scenario.scenario, p.streams[0].own_scenario.display().to_string(), "the emulator reads the run's own copy");
    // A seed given, or the return scenario's own, wins over the rule.
    let p = plan(&["Normal", "--return-seed", "5"], &[0, 1]);
    assert_eq!(p.emulator.channels.feedback.return_seed, Some(5));
    let a = run_args(&["Normal"]);
    let mut r = resolved(&a);
    r.paths[0].2.seed = Some(11);
    assert_eq!(Plan::new(&a, &r, 7, "r1".into(), &[0, 1]).unwrap().emulator.channels.feedback.return_seed, Some(11));
    // Without feedback, no seed for it and the emulator is told.
    let p = plan(&["Normal", "--no-feedback"], &[0, 1]);
    assert_eq!((p.emulator.channels.feedback.return_seed, p.emulator.channels.feedback.no_feedback), (None, true));
    assert!(p.emulator.to_argv().contains(&"--no-feedback".to_string()));
    assert_eq!(p.seeds.paths.get("video"), None);
}

#[test]
fn each_stream_has_its_run_id_seed_directory_and_scenario_copy() {
    let p = plan(&["Normal", "--streams", "3"], &[0, 1]);
    assert_eq!(p.streams.len(), 3);
    let s2 = &p.streams[2];
    assert_eq!((s2.run_id.as_str(), s2.seed), ("r1-s2", seeds::stream(7, 2)));
    assert_eq!(s2.out, PathBuf::from("out/r1/stream-2"));
    assert_eq!(s2.console.as_ref().unwrap().seed, Some(s2.seed));
    assert_eq!((s2.console.as_ref().unwrap().nap_us, s2.simulator.as_ref().unwrap().nap_us, s2.simulator.as_ref().unwrap().spin), (Some(STREAM_NAP_US), Some(STREAM_NAP_US), false));
    assert_eq!(p.emulator.stream.streams, 3);
    assert_eq!(p.emulator.stream.stream_scenario[1], format!("2={}", s2.own_scenario.display()));
    // Each lane derives its return seed from its own seed, as before.
    assert_eq!(p.emulator.channels.feedback.return_seed, None);
}

#[test]
fn a_rate_outside_the_physical_range_is_refused_naming_the_flag() {
    for bad in ["0", "-5", "NaN", "inf", "0.0001", "2e7", "fast"] {
        let flag = format!("--rate-hz={bad}");
        let e = Cli::try_parse_from(["netfi", "run", "Normal", &flag]).err().expect(bad).to_string();
        assert!(e.contains("--rate-hz") && e.contains("0.001 Hz and 1 MHz") || bad == "fast", "{bad}: {e}");
    }
    assert_eq!(run_args(&["Normal", "--rate-hz", "0.001"]).source.rate_hz, Some(0.001));
    assert_eq!(run_args(&["Normal", "--rate-hz", "1000000"]).source.rate_hz, Some(1e6));
}

#[test]
fn the_lab_s_console_and_robot_are_not_started_and_the_emulator_meets_them() {
    use crate::service::args::run::LAB_ROBOT_WAIT_S;
    let p = plan(&["Normal", "--console", "lab", "--robot", "lab"], &[0, 1]);
    assert!(p.streams[0].console.is_none() && p.streams[0].simulator.is_none());
    assert_eq!(p.until_s, None, "the lab's console ends the run");
    assert_eq!(p.emulator.wait_for_peer_s, Some(LAB_ROBOT_WAIT_S), "the lab's robot is waited for on iceoryx2");
    let p = plan(&["Normal", "--ingress", "udp://:36000", "--console-from", "first", "--egress", "udp://127.0.0.1:36001", "--duration-s", "5"], &[0, 1]);
    assert!(p.streams[0].console.is_none() && p.streams[0].simulator.is_none(), "UDP ends are the lab's");
    assert_eq!(p.until_s, Some(5.0));
    assert_eq!(p.emulator.wait_for_peer_s, None, "a UDP robot does not subscribe");
    assert_eq!((p.emulator.ends.ingress.to_string(), p.emulator.ends.egress.to_string()), ("udp://127.0.0.1:36000".into(), "udp://127.0.0.1:36001".into()));
    assert!(p.emulator.to_argv().windows(2).any(|w| w == ["--console-from", "first"]), "{:?}", p.emulator.to_argv());
    // netfi's own robot behind the lab's console.
    let p = plan(&["Normal", "--console", "lab"], &[0, 1]);
    assert!(p.streams[0].console.is_none() && p.streams[0].simulator.is_some());
    assert_eq!(p.emulator.wait_for_peer_s, None);
    // A run of netfi's own ends is as it was.
    let p = plan(&["Normal"], &[0, 1]);
    assert!(p.streams[0].console.is_some() && p.streams[0].simulator.is_some() && p.until_s == Some(p.planned_s));
}

#[test]
fn netfi_s_own_ends_speak_iceoryx2_and_the_lab_s_join_one_stream() {
    let e = run_args(&["Normal", "--ingress", "udp://:36000", "--console", "own"]).validate().unwrap_err().to_string();
    assert_eq!(e, "netfi's own console speaks iceoryx2 only, and --ingress is udp://127.0.0.1:36000: give --console lab to join the lab's console there");
    let e = run_args(&["Normal", "--egress", "udp://127.0.0.1:5", "--robot", "own"]).validate().unwrap_err().to_string();
    assert!(e.starts_with("netfi's own robot speaks iceoryx2 only"), "{e}");
    assert!(matches!(run_args(&["Normal", "--console", "lab", "--streams", "2"]).validate(), Err(ArgsError::LabStreams { streams: 2 })));
    run_args(&["Normal", "--console", "lab", "--robot", "lab"]).validate().unwrap();
}
