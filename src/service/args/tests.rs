use super::*;
use crate::service::channel::feedback::ReturnArgs;
use crate::service::channel::{ChannelArgs, ChannelEndArgs};
use clap::{CommandFactory, Parser};

/// The four commands that take these arguments, as the `netfi` command
/// line declares them (the plan's tests parse what it renders with it).
#[derive(Parser)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) cmd: Cmd,
}

#[derive(clap::Subcommand)]
pub(crate) enum Cmd {
    Run(RunArgs),
    Console(ConsoleArgs),
    Emulator(EmulatorArgs),
    Simulator(SimulatorArgs),
}

fn parse(role: &str, argv: &[String]) -> Result<Cmd, clap::Error> {
    Cli::try_parse_from([vec!["netfi".to_string(), role.to_string()], argv.to_vec()].concat()).map(|c| c.cmd)
}

/// Video on, every one of its flags off its default.
fn video() -> crate::service::channel::video::VideoArgs {
    crate::service::channel::video::VideoArgs {
        video_mbps: Some(2.5),
        video_hz: 30.0,
        video_gop: 12,
        video_key_ratio: 6.5,
        video_max_bytes: 123_456,
        video_scenario: Some("PLM-1".into()),
        video_seed: Some(99),
    }
}

#[test]
fn a_console_parses_back_what_it_renders() {
    let c = ConsoleArgs {
        run_id: "r9".into(),
        source: SourceArgs { rate_hz: Some(250.5), frames: None, duration_s: Some(1.25), capture: Some("c.lz4".into()), capture_max_records: Some(5000) },
        seed: Some(u64::MAX),
        pin: PinArgs { core: None, avoid_core: Some(3) },
        out: "o/c".into(),
        no_direct: true,
        wait_for_peer_s: 2.5,
        feedback_wait_s: 0.0,
        live: true,
        nap_us: Some(0),
        channels: ChannelEndArgs { video: video(), ..Default::default() },
    };
    let Ok(Cmd::Console(back)) = parse("console", &c.to_argv()) else { panic!("{:?}", c.to_argv()) };
    assert_eq!(back, c);
    let frames = ConsoleArgs { source: SourceArgs { frames: Some(17), duration_s: None, ..c.source.clone() }, pin: PinArgs { core: Some(2), avoid_core: None }, ..c };
    let Ok(Cmd::Console(back)) = parse("console", &frames.to_argv()) else { panic!("{:?}", frames.to_argv()) };
    assert_eq!(back, frames);
}

#[test]
fn an_emulator_parses_back_what_it_renders() {
    let e = EmulatorArgs {
        run_id: Some("r9".into()),
        scenario: ScenarioArgs { scenario: "PLM-2".into(), seed: Some(3), queue_capacity: Some(77) },
        placement: EmulatorPlacement { core: Some(1), no_pin: false, rt_priority: Some(5), isolate: true },
        drop_bad_checksum: true,
        kinematics: true,
        expected_frames: 1234,
        out: "o/e".into(),
        wait_for_peer_s: Some(1.5),
        channels: ChannelArgs { feedback: ReturnArgs { return_scenario: Some("DLM-1".into()), return_seed: Some(8), no_feedback: false }, video: video(), ..Default::default() },
        ends: EndsArgs::default(),
        transports: Default::default(),
        control: ControlArgs { telemetry_ms: 250, reorder_queue: true, fifo_queue: false, no_control: true },
        stream: StreamArgs::default(),
        ros2: Default::default(),
    };
    let Ok(Cmd::Emulator(back)) = parse("emulator", &e.to_argv()) else { panic!("{:?}", e.to_argv()) };
    assert_eq!(back, e);
    // Several streams, no feedback, unpinned.
    let streams = StreamArgs { streams: 3, stream_scenario: vec!["1=PLM-1".into(), "2=x.toml".into()] };
    let e2 = EmulatorArgs {
        stream: streams,
        channels: ChannelArgs { feedback: ReturnArgs { no_feedback: true, ..Default::default() }, ..Default::default() },
        placement: EmulatorPlacement { core: None, no_pin: true, rt_priority: None, isolate: false },
        ..e.clone()
    };
    let Ok(Cmd::Emulator(back)) = parse("emulator", &e2.to_argv()) else { panic!("{:?}", e2.to_argv()) };
    assert_eq!(back, e2);
    // A UDP bridge: every UDP flag off its default.
    let udp = crate::transport::udp::UdpArgs {
        payload: crate::transport::Payload::Raw,
        egress_bind: Some("127.0.0.1:4002".parse().unwrap()),
        console_from: Some("127.0.0.1:4003".parse().unwrap()),
        robot_from: Some("127.0.0.1:4004".parse().unwrap()),
        return_to: Some("127.0.0.1:4004".parse().unwrap()),
        no_return: false,
        udp_buffer_bytes: 65536,
    };
    let ends = EndsArgs { ingress: "udp://127.0.0.1:4000".parse().unwrap(), egress: "udp://127.0.0.1:4001".parse().unwrap(), idle_end_ms: Some(500.5) };
    let transports = crate::transport::TransportArgs { udp, ..Default::default() };
    let e3 = EmulatorArgs { ends, transports, channels: ChannelArgs { video: Default::default(), ..e.channels.clone() }, wait_for_peer_s: None, ..e };
    let Ok(Cmd::Emulator(back)) = parse("emulator", &e3.to_argv()) else { panic!("{:?}", e3.to_argv()) };
    assert_eq!(back, e3);
    e3.validate().unwrap();
    // ROS 2 lanes: every ROS 2 flag off its default.
    let ros2 = crate::transport::ros2::Ros2Args {
        ros2_topic: vec!["/MTMR/measured_cp=/PSM1/servo_cp".into(), "/MTML/measured_cp=/PSM2/servo_cp".into()],
        ros2_return: vec!["/PSM1/measured_cp=/MTMR/state".into()],
        ros2_type: vec!["/MTMR/measured_cp=geometry_msgs/msg/PoseStamped".into()],
        ros2_qos: vec!["/PSM1/servo_cp=best_effort,depth=1".into()],
        ros2_domain: Some(7),
        ros2_max_bytes: 4096,
        ros2_discovery_s: 2.5,
        ros2_linger_ms: 250.0,
    };
    let e4 = EmulatorArgs { ros2, ends: EndsArgs::default(), transports: Default::default(), ..e3 };
    let Ok(Cmd::Emulator(back)) = parse("emulator", &e4.to_argv()) else { panic!("{:?}", e4.to_argv()) };
    assert_eq!(back, e4);
}

#[test]
fn a_simulator_parses_back_what_it_renders() {
    let s = SimulatorArgs {
        run_id: "r9".into(),
        pin: PinArgs { core: Some(0), avoid_core: None },
        stall_ms: 2.5,
        drop_bad_checksum: true,
        spin: true,
        out: "o/s".into(),
        nap_us: Some(300),
        channels: ChannelEndArgs { video: video(), ..Default::default() },
    };
    let Ok(Cmd::Simulator(back)) = parse("simulator", &s.to_argv()) else { panic!("{:?}", s.to_argv()) };
    assert_eq!(back, s);
}

#[test]
fn a_run_parses_back_what_it_renders() {
    let r = RunArgs {
        scenario: ScenarioArgs { scenario: "config/scenarios/x.toml".into(), seed: Some(3), queue_capacity: Some(77) },
        source: SourceArgs { rate_hz: Some(250.5), frames: None, duration_s: Some(1.25), capture: Some("c.lz4".into()), capture_max_records: Some(5000) },
        placement: RunPlacement {
            emulator: EmulatorPlacement { core: Some(1), no_pin: false, rt_priority: Some(5), isolate: false },
            no_isolate: true,
            console_core: Some(0),
            simulator_core: Some(2),
        },
        drop_bad_checksum: true,
        out: Some("o/r".into()),
        out_owned_by_other: true,
        report_json: Some("o/r.json".into()),
        run_id: Some("r9".into()),
        json: true,
        channels: ChannelArgs { feedback: ReturnArgs { return_scenario: Some("DLM-1".into()), return_seed: Some(8), no_feedback: false }, video: video(), ..Default::default() },
        no_direct: true,
        control: ControlArgs { telemetry_ms: 250, reorder_queue: true, fifo_queue: false, no_control: false },
        stream: StreamArgs::default(),
        peers: PeersArgs::default(),
    };
    assert_eq!(RunArgs::from_argv(r.to_argv()).unwrap(), r, "{:?}", r.to_argv());
    let Ok(Cmd::Run(back)) = parse("run", &r.to_argv()) else { panic!("{:?}", r.to_argv()) };
    assert_eq!(back, r, "as `netfi run` reads it");
    // Several streams, no feedback, unpinned, the scenario a word that reads as a flag.
    let r2 = RunArgs {
        scenario: ScenarioArgs::named("-odd.toml"),
        source: SourceArgs { frames: Some(17), duration_s: None, ..r.source.clone() },
        placement: RunPlacement { emulator: EmulatorPlacement { core: None, no_pin: true, rt_priority: None, isolate: true }, ..Default::default() },
        channels: ChannelArgs { feedback: ReturnArgs { no_feedback: true, ..Default::default() }, ..Default::default() },
        stream: StreamArgs { streams: 3, stream_scenario: vec!["1=PLM-1".into(), "2=x.toml".into()] },
        ..r
    };
    assert_eq!(RunArgs::from_argv(r2.to_argv()).unwrap(), r2, "{:?}", r2.to_argv());
    // A run at its defaults is its scenario alone.
    assert_eq!(RunArgs::new("Normal").to_argv(), ["Normal"]);
    assert_eq!(RunArgs::from_argv(["Normal"]).unwrap(), RunArgs::new("Normal"), "RunArgs::new gives clap's defaults");
}

#[test]
fn a_refused_run_says_what_clap_says_in_one_line() {
    let e = RunArgs::from_argv(["Normal", "--rt-priority", "0"]).unwrap_err();
    let said = refusal(&e);
    assert!(said.starts_with("invalid value '0' for '--rt-priority <RT_PRIORITY>'"), "{said}");
    assert!(!said.contains('\n') && !said.contains("Usage"), "{said}");
    assert_eq!(refusal(&RunArgs::from_argv(["Normal", "--no-isolat"]).unwrap_err()), "unexpected argument '--no-isolat' found");
}

/// A command of `T`'s arguments alone.
fn command_of<T: clap::Args>() -> clap::Command {
    T::augment_args(clap::Command::new("netfi").no_binary_name(true))
}

/// The words that give `arg` the values `values` (none: a switch; a
/// positional: the values alone).
fn words_of(arg: &clap::Arg, values: &[String]) -> Vec<String> {
    match arg.get_long() {
        None => values.to_vec(),
        Some(long) if values.is_empty() => vec![format!("--{long}")],
        Some(long) => values.iter().flat_map(|v| [format!("--{long}"), v.clone()]).collect(),
    }
}

/// Values to try for `arg`, numbered `n` so that no two arguments are
/// given the same: a switch takes none; otherwise its possible values,
/// then numbers, endpoints and addresses; a repeatable flag two of each.
fn candidates(arg: &clap::Arg, n: usize) -> Vec<Vec<String>> {
    use clap::ArgAction;
    if matches!(arg.get_action(), ArgAction::SetTrue) {
        return vec![Vec::new()];
    }
    let one = |n: usize| -> Vec<String> {
        let mut v: Vec<String> = arg.get_possible_values().iter().map(|p| p.get_name().to_string()).collect();
        for k in n..n + 3 {
            v.extend([format!("{k}.25"), k.to_string(), format!("udp://127.0.0.1:{}", 4000 + k), format!("127.0.0.1:{}", 4000 + k)]);
        }
        v
    };
    match arg.get_action() {
        ArgAction::Append => one(n).into_iter().zip(one(n + 100)).map(|(a, b)| vec![a, b]).collect(),
        _ => one(n).into_iter().map(|v| vec![v]).collect(),
    }
}

/// Walks every argument of `T`'s command: gives each a value off its
/// default (the first candidate that parses and changes the value), puts
/// them into as few argvs as parse with each argument kept (none
/// conflicting with or overriding another), and for each argv: parse,
/// render, parse again; the two values are equal, and every argument given
/// is in the rendered argv. An argument added without its renderer, or
/// rendered under another's flag or value, fails here.
fn every_argument_renders<T>()
where
    T: clap::Args + clap::FromArgMatches + Render + PartialEq + std::fmt::Debug,
{
    use clap::parser::ValueSource;
    let name = std::any::type_name::<T>();
    let cmd = command_of::<T>();
    let parse = |argv: &[String]| -> Result<(clap::ArgMatches, T), clap::Error> {
        let m = cmd.clone().try_get_matches_from(argv)?;
        let v = T::from_arg_matches(&m)?;
        Ok((m, v))
    };
    let given = |m: &clap::ArgMatches, a: &clap::Arg| m.value_source(a.get_id().as_str()) == Some(ValueSource::CommandLine);
    let args: Vec<(usize, &clap::Arg)> = cmd.get_arguments().enumerate().map(|(n, a)| (n + 2, a)).collect();
    assert!(args.len() >= 6, "{name}: {} arguments", args.len());
    let (required, optional): (Vec<_>, Vec<_>) = args.iter().copied().partition(|(_, a)| a.is_required_set());
    let head: Vec<String> = required.iter().flat_map(|&(n, a)| words_of(a, &candidates(a, n)[0])).collect();
    let (_, base) = parse(&head).unwrap_or_else(|e| panic!("{name}: the required arguments alone {head:?}: {e}"));
    let with = |words: &[&Vec<String>]| [vec![head.clone()], words.iter().map(|w| w.to_vec()).collect()].concat().concat();
    let mut groups: Vec<Vec<(&clap::Arg, Vec<String>)>> = Vec::new();
    for &(n, a) in &optional {
        let w = candidates(a, n)
            .iter()
            .map(|v| words_of(a, v))
            .find(|w| parse(&with(&[w])).is_ok_and(|(_, v)| v != base))
            .unwrap_or_else(|| panic!("{name}: no candidate value of `{}` parses to a value off the default", a.get_id()));
        let fits = |g: &Vec<(&clap::Arg, Vec<String>)>| {
            let words: Vec<&Vec<String>> = g.iter().map(|(_, w)| w).chain([&w]).collect();
            parse(&with(&words)).is_ok_and(|(m, _)| g.iter().map(|(a, _)| *a).chain([a]).all(|a| given(&m, a)))
        };
        match groups.iter_mut().find(|g| fits(g)) {
            Some(g) => g.push((a, w)),
            None => groups.push(vec![(a, w)]),
        }
    }
    let mut seen = 0;
    for g in &groups {
        let argv = with(&g.iter().map(|(_, w)| w).collect::<Vec<_>>());
        let (_, first) = parse(&argv).unwrap();
        let rendered = super::argv::render(&first);
        let (m, again) = parse(&rendered).unwrap_or_else(|e| panic!("{name}: {rendered:?} does not parse: {e}"));
        assert_eq!(again, first, "{name}: {argv:?} rendered as {rendered:?}");
        for a in required.iter().map(|&(_, a)| a).chain(g.iter().map(|(a, _)| *a)) {
            assert!(given(&m, a), "{name}: `{}` is not in the rendered {rendered:?} (given {argv:?})", a.get_id());
        }
        seen += g.len();
    }
    assert_eq!(seen + required.len(), args.len(), "{name}: every argument walked");
}

#[test]
fn every_argument_of_the_run_renders_and_parses_back() {
    every_argument_renders::<RunArgs>();
}

#[test]
fn every_argument_of_the_services_renders_and_parses_back() {
    every_argument_renders::<ConsoleArgs>();
    every_argument_renders::<EmulatorArgs>();
    every_argument_renders::<SimulatorArgs>();
}

#[test]
fn the_run_and_the_emulator_take_the_same_groups_each_with_its_help() {
    let want = StreamArgs { streams: 3, stream_scenario: vec!["1=PLM-1".into()] };
    let flags = ["--streams", "3", "--stream-scenario", "1=PLM-1"].map(String::from);
    let with = |head: &[&str]| [head.iter().map(|s| s.to_string()).collect::<Vec<_>>(), flags.to_vec()].concat();
    let Ok(Cmd::Run(r)) = parse("run", &with(&["Normal"])) else { unreachable!() };
    assert_eq!(r.stream, want);
    let Ok(Cmd::Emulator(e)) = parse("emulator", &with(&["--scenario", "Normal"])) else { unreachable!() };
    assert_eq!(e.stream, want);
    assert_eq!(r.scenario, e.scenario, "the scenario positional for the run, `--scenario` for the emulator");
    assert!(e.to_argv().windows(4).any(|w| w == flags), "{:?}", e.to_argv());
    let cmd = Cli::command();
    let help = |sub: &str, arg: &str| {
        let sub = cmd.find_subcommand(sub).unwrap();
        sub.get_arguments().find(|a| a.get_id() == arg).and_then(|a| a.get_help()).map(|h| h.to_string()).unwrap()
    };
    assert_eq!(help("emulator", "streams"), help::EMULATOR_STREAMS[0]);
    assert_eq!(help("emulator", "stream_scenario"), help::EMULATOR_STREAMS[1]);
    assert!(help("run", "streams").starts_with("Console → robot pairs through the one emulator (1 to 64)"));
    assert!(help("run", "stream_scenario").ends_with("Streams not named take the run's scenario"));
    assert_eq!(help("emulator", "return_scenario"), help::EMULATOR_RETURN[0]);
    assert!(help("run", "return_scenario").starts_with("Pass the robot's feedback back to the console"));
    assert_eq!(help("run", "seed"), help::RUN_SEED);
    assert_eq!(help("run", "no_feedback"), help::RUN_NO_FEEDBACK);
    assert_eq!(help("run", "core"), help::RUN_PLACEMENT[0]);
    assert!(help("emulator", "core").starts_with("Core to pin the emulator's loop to"));
    assert!(cmd.find_subcommand("run").unwrap().get_arguments().any(|a| a.get_long() == Some("emulator-core")));
}

/// Every numeric flag of the run and the services, a value past its range
/// on each side, and a word of the message.
const OUT_OF_RANGE: &[(&str, &str, &[&str], &str)] = &[
    ("run", "--duration-s", &["0", "1e30", "604801"], "a week"),
    ("run", "--frames", &["0", "18446744073709551615"], "1..="),
    ("run", "--rate-hz", &["0", "2e6", "1e30"], "1 MHz"),
    ("run", "--queue-capacity", &["0", "16777217"], "1..=16777216"),
    ("run", "--emulator-core", &["1024"], "0..=1023"),
    ("run", "--console-core", &["18446744073709551615"], "0..=1023"),
    ("run", "--simulator-core", &["1024"], "0..=1023"),
    ("run", "--rt-priority", &["0", "100"], "1..=99"),
    ("run", "--telemetry-ms", &["18446744073709551615", "3600001"], "0..=3600000"),
    ("run", "--streams", &["0", "65"], "1..=64"),
    ("console", "--wait-for-peer-s", &["1e30", "3601"], "an hour"),
    ("console", "--feedback-wait-s", &["1e30"], "an hour"),
    ("console", "--nap-us", &["1000001"], "0..=1000000"),
    ("console", "--duration-s", &["1e300"], "a week"),
    ("console", "--core", &["4096"], "0..=1023"),
    ("console", "--avoid-core", &["4096"], "0..=1023"),
    ("emulator", "--expected-frames", &["0", "18446744073709551615"], "1..="),
    ("emulator", "--idle-end-ms", &["0", "1e30"], "a week"),
    ("emulator", "--wait-for-peer-s", &["1e30"], "an hour"),
    ("emulator", "--udp-buffer-bytes", &["0", "4294967296"], "1..=1073741824"),
    ("emulator", "--core", &["1024"], "0..=1023"),
    ("emulator", "--ros2-discovery-s", &["1e300", "3601"], "an hour"),
    ("emulator", "--ros2-linger-ms", &["1e300", "3600001"], "an hour"),
    ("run", "--ros2-discovery-s", &["1e300"], "an hour"),
    ("emulator", "--queue-capacity", &["0"], "1..=16777216"),
    ("emulator", "--telemetry-ms", &["18446744073709551615"], "0..=3600000"),
    ("simulator", "--stall-ms", &["0", "1e30"], "an hour"),
    ("simulator", "--nap-us", &["18446744073709551615"], "0..=1000000"),
];

#[test]
fn every_numeric_flag_out_of_range_is_refused_naming_the_flag_and_its_range() {
    let head = |role: &str| match role {
        "run" => vec!["Normal".to_string()],
        "emulator" => vec!["--scenario".into(), "Normal".into()],
        _ => vec!["--run-id".into(), "r".into()],
    };
    for (role, flag, bad, range) in OUT_OF_RANGE {
        for v in *bad {
            let argv = [head(role), vec![format!("{flag}={v}")]].concat();
            let e = parse(role, &argv).err().unwrap_or_else(|| panic!("{role} {flag} {v} was taken")).to_string();
            assert!(e.contains(flag) && e.contains(range), "{role} {flag} {v}: {e}");
        }
    }
}

#[test]
fn the_largest_values_in_range_are_taken() {
    let argv = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let ok = parse("run", &argv(&["Normal", "--duration-s", "604800", "--telemetry-ms", "3600000", "--queue-capacity", "16777216"]));
    let Ok(Cmd::Run(r)) = ok else { panic!() };
    assert_eq!((r.source.duration_s, r.control.telemetry_ms, r.scenario.queue_capacity), (Some(604800.0), 3_600_000, Some(1 << 24)));
    r.validate().unwrap();
}

#[test]
fn video_flags_without_video_are_refused() {
    let argv = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    for flag in [["--video-hz", "30"], ["--video-gop", "10"], ["--video-key-ratio", "2"], ["--video-max-bytes", "10"], ["--video-seed", "3"]] {
        let Ok(Cmd::Run(r)) = parse("run", &argv(&["Normal", flag[0], flag[1]])) else { panic!("{flag:?}") };
        let e = r.validate().unwrap_err().to_string();
        assert!(e.contains(flag[0]) && e.contains("need --video-mbps"), "{flag:?}: {e}");
    }
    let Ok(Cmd::Run(r)) = parse("run", &argv(&["Normal", "--video-mbps", "2", "--video-hz", "30"])) else { panic!() };
    r.validate().unwrap();
}

#[test]
fn a_core_is_checked_once_against_the_cores_this_process_may_use() {
    use crate::service::args::check_core;
    assert!(check_core("--core", Some(1), &[0, 1]).is_ok());
    assert!(check_core("--core", None, &[0]).is_ok());
    let e = check_core("--core", Some(2), &[0, 1]).unwrap_err().to_string();
    assert!(e.contains("--core 2") && e.contains("[0, 1]"), "{e}");
    let argv = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let Ok(Cmd::Run(r)) = parse("run", &argv(&["Normal", "--emulator-core", "1", "--console-core", "1"])) else { panic!() };
    let w = r.placement.shared_core_warnings();
    assert!(w.len() == 1 && w[0].contains("--console-core 1 is the emulator's core"), "{w:?}");
    let Ok(Cmd::Run(r)) = parse("run", &argv(&["Normal", "--emulator-core", "1", "--console-core", "0"])) else { panic!() };
    assert!(r.placement.shared_core_warnings().is_empty());
}
