//! A transport and a reverse channel that exist only in test builds, each
//! one folder and one line in its registry (`src/transport/unixgram`,
//! `src/service/channel/haptic`), driven through the real runner: what a
//! new transport or channel gets from the runner, the plan, the checks and
//! the report without naming it anywhere else.

use super::{spawn_run, u};
use crate::common::machine;
use crate::common::netfi::netfi;
use netfi::frame::ItpView;
use serde_json::Value;
use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

/// A valid ITP frame with sequence `seq`.
fn itp(seq: u32) -> [u8; 124] {
    let mut b = [0u8; 124];
    let mut v = ItpView::new_unchecked(&mut b[..]);
    v.set_sequence(seq);
    v.set_delx([(seq % 7) as i32, 1]);
    v.set_surgeon_mode(1);
    v.fill_checksum();
    b
}

/// `netfi scenario check`'s fate of each of `n` frames, by index.
fn check_fates(scenario: &str, seed: u64, n: u64, dir: &std::path::Path) -> Vec<String> {
    let trace = dir.join("check.csv");
    let o = netfi()
        .args(["scenario", "check", scenario, "--frames", &n.to_string(), "--seed", &seed.to_string(), "--json", "--trace"])
        .arg(&trace)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&trace).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let fate = head.iter().position(|h| *h == "fate").expect("a fate column");
    lines.map(|l| l.split(',').nth(fate).unwrap().to_string()).collect()
}

#[test]
fn a_test_only_transport_carries_a_lab_run_with_the_fates_scenario_check_gives() {
    let _guard = machine::alone();
    let dir = super::out_dir("unixgram");
    std::fs::create_dir_all(&dir).unwrap();
    let (ingress, egress) = (dir.join("emulator.sock"), dir.join("robot.sock"));
    // The lab's robot: a socket bound before the run starts.
    let robot = UnixDatagram::bind(&egress).unwrap();
    robot.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let out = dir.join("out");
    let mut run = spawn_run(
        &out,
        &[
            "PLM-2",
            "--seed",
            "3",
            "--console",
            "lab",
            "--robot",
            "lab",
            "--ingress",
            &format!("unixgram:{}", ingress.display()),
            "--egress",
            &format!("unixgram:{}", egress.display()),
        ],
    );
    // The lab's console: sends once the emulator's socket is bound.
    let t0 = Instant::now();
    while !ingress.exists() {
        if let Some(s) = run.try_wait().unwrap() {
            let o = run.wait_with_output().unwrap();
            panic!("the run ended ({s}) before its ingress was bound:\n{}", String::from_utf8_lossy(&o.stderr));
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "no ingress socket within 60 s");
        std::thread::sleep(Duration::from_millis(10));
    }
    let console = UnixDatagram::unbound().unwrap();
    let n = 2000u32;
    let receiver = std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            let len = robot.recv(&mut buf).expect("the robot hears the end of the stream");
            if len == 0 {
                break got;
            }
            assert_eq!(len, 124);
            got.push(ItpView::new_unchecked(&buf[..len]).sequence());
        }
    });
    for i in 0..n {
        console.send_to(&itp(i), &ingress).unwrap();
        std::thread::sleep(Duration::from_micros(500));
    }
    console.send_to(&[], &ingress).unwrap();
    let got = receiver.join().unwrap();
    let o = run.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let r: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"));

    let f = &r["frames"];
    assert_eq!(u(&f["entered"]), u64::from(n), "{f}");
    assert_eq!(u(&f["delivered"]), got.len() as u64, "{f}");
    let fates = check_fates("PLM-2", 3, u64::from(n), &dir);
    let expected: Vec<u32> = (0..n).filter(|&i| fates[i as usize] == "delivered").collect();
    assert!(expected.len() < n as usize, "PLM-2 drops some of {n}");
    assert_eq!(got, expected, "every fate is the one scenario check gives");
    assert!(!ingress.exists(), "the ingress socket is removed with the run");
    std::fs::remove_dir_all(&dir).ok();
}

/// Retries `f` until it gives a value (the run's services appear once its
/// emulator is up), within a minute.
fn retry<T, E: std::fmt::Debug>(what: &str, mut f: impl FnMut() -> Result<T, E>) -> T {
    let t0 = Instant::now();
    loop {
        match f() {
            Ok(v) => return v,
            Err(e) if t0.elapsed() > Duration::from_secs(60) => panic!("{what}: {e:?}"),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

#[test]
fn a_test_only_channel_carries_its_samples_through_its_own_scenario_in_a_real_run() {
    use netfi::sample::FrameSample;
    use netfi::service::channel::haptic::{HapticSample, HAPTIC, HAPTIC_OUT};
    use netfi::transport::{open_node, Port, Role};

    let _guard = machine::alone();
    let dir = super::out_dir("haptic");
    let out = dir.join("out");
    let run_id = format!("hap{}", std::process::id());
    let mut run = spawn_run(
        &out,
        &["Normal", "--console", "lab", "--robot", "lab", "--run-id", &run_id, "--haptic", "--haptic-scenario", "PLM-2", "--haptic-seed", "5"],
    );
    // The lab's robot and console, both this test: frames in, frames out,
    // force readings back.
    let robot = retry("the robot's node", || open_node(&run_id, Role::Simulator));
    let mut frames_out = retry("the robot's frame port", || robot.subscriber(Port::EMULATOR));
    let mut forces = retry("the robot's haptic port", || robot.publisher_of::<HapticSample>(HAPTIC));
    let console = retry("the console's node", || open_node(&run_id, Role::Console));
    let mut haptic_out = retry("the console's haptic port", || console.subscriber_of::<HapticSample>(HAPTIC_OUT));
    let mut frames_in = retry("the console's frame port", || console.publisher(Port::CONSOLE));
    let ready = out.join("emulator.ready");
    let t0 = Instant::now();
    while !ready.exists() {
        assert!(run.try_wait().unwrap().is_none(), "the run ended before its emulator was ready");
        assert!(t0.elapsed() < Duration::from_secs(60), "no emulator within 60 s");
        std::thread::sleep(Duration::from_millis(10));
    }

    let n = 1000u64;
    let (mut forwarded, mut came_back) = (0u64, Vec::new());
    let take_back = |haptic_out: &mut netfi::transport::FrameSubscriber<HapticSample>, came_back: &mut Vec<u64>| -> bool {
        while let Some(s) = haptic_out.try_recv().unwrap() {
            if s.is_end() {
                return true;
            }
            came_back.push(s.robot_index);
        }
        false
    };
    for i in 0..n {
        let mut f = FrameSample { console_index: i, send_ns: netfi::clock::now_ns(), ..FrameSample::ZERO };
        netfi::frame::ItpFrame::parse(&ItpView::new_unchecked(&itp(i as u32)[..])).unwrap().write_to_sample(&mut f);
        frames_in.send(&f).unwrap();
        let reading = HapticSample { send_ns: netfi::clock::now_ns(), robot_index: i, force_mn: [i as i32, -1, 2], ..HapticSample::default() };
        forces.send(&reading).unwrap();
        while frames_out.try_recv().unwrap().is_some() {
            forwarded += 1;
        }
        take_back(&mut haptic_out, &mut came_back);
        std::thread::sleep(Duration::from_micros(500));
    }
    forces.send(&HapticSample::end_marker(n)).unwrap();
    frames_in.send(&FrameSample::end_marker(n)).unwrap();
    let t0 = Instant::now();
    let mut ended = false;
    while !ended && t0.elapsed() < Duration::from_secs(30) {
        while frames_out.try_recv().unwrap().is_some_and(|f| !f.is_end()) {
            forwarded += 1;
        }
        ended = take_back(&mut haptic_out, &mut came_back);
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(ended, "the console hears the haptic path's end");
    let o = run.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let r: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"));

    assert_eq!(u(&r["frames"]["delivered"]), n, "Normal delivers every frame");
    assert_eq!(forwarded, n, "the robot got every frame");
    let h = &r["haptic"];
    assert_eq!((u(&h["entered"]), u(&h["sent_by_robot"]), &h["balanced"]), (n, n, &Value::Bool(true)), "{h}");
    assert_eq!(u(&h["delivered"]), came_back.len() as u64, "{h}");
    // The haptic path's own scenario and seed decided each reading's fate,
    // as scenario check decides them.
    let fates = check_fates("PLM-2", 5, n, &dir);
    let expected: Vec<u64> = (0..n).filter(|&i| fates[i as usize] == "delivered").collect();
    assert!(expected.len() < n as usize, "PLM-2 drops some of {n}");
    assert_eq!(came_back, expected);
    drop((frames_in, haptic_out, console, frames_out, forces, robot));
    std::fs::remove_dir_all(&dir).ok();
}
