//! A run no `netfi run` started: the emulator alone (`netfi-emulator`),
//! its console and robot started by hand as other programs would be
//! (netfi's own `netfi-console` and `netfi-simulator`, named by
//! `--run-id`). `netfi report DIR` and `--html` give its report from what
//! the services wrote, with the same sections as a `netfi run`'s, and say
//! which parts are missing when a client wrote none.

use crate::common::netfi::emulator_pin;
use super::{copy_dir, netfi, polylines, svg, temp_dir, text_of, the_run};
use crate::common::machine;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

fn service(name: &str) -> Command {
    let bin = match name {
        "emulator" => env!("CARGO_BIN_EXE_netfi-emulator"),
        "console" => env!("CARGO_BIN_EXE_netfi-console"),
        _ => env!("CARGO_BIN_EXE_netfi-simulator"),
    };
    let mut c = Command::new(bin);
    c.stdout(Stdio::piped()).stderr(Stdio::piped());
    c
}

/// Waits for `child` to end on its own (at most a minute), killing it
/// after that; its output.
fn finish(mut child: Child, what: &str) -> Output {
    let deadline = Instant::now() + Duration::from_secs(60);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("the {what} did not end: {:?}", child.wait_with_output().unwrap());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "the {what} failed: {}", String::from_utf8_lossy(&o.stderr));
    o
}

/// The directory of a DLM-2 run of 1 000 frames (made once): the emulator
/// started alone, then the robot, then the console, each by hand.
fn the_foreign_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let _guard = machine::alone();
        let out = temp_dir("foreign");
        let run_id = format!("html-foreign-{}", std::process::id());
        let pin = emulator_pin();
        let emulator = service("emulator")
            .args(["--run-id", &run_id, "--scenario", "DLM-2", "--seed", "5", "--expected-frames", "1000", "--out"])
            .arg(&out)
            .args(&pin)
            .spawn()
            .unwrap();
        crate::common::wait_file(&out.join("emulator.ready"));
        let robot = service("simulator").args(["--run-id", &run_id, "--out"]).arg(&out).spawn().unwrap();
        let console = service("console").args(["--run-id", &run_id, "--frames", "1000", "--seed", "3", "--out"]).arg(&out).spawn().unwrap();
        finish(console, "console");
        finish(emulator, "emulator");
        finish(robot, "robot");
        assert!(!out.join("report.json").exists(), "no runner, no report.json");
        out
    })
}

fn report_text(dir: &Path) -> String {
    let o = netfi().arg("report").arg(dir).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

/// The first words of the lines of a run report's sections: the frames,
/// loss, each stage, delays, overhead, the delay law, kinematics, the
/// feedback loop, the host, peers and files.
const SECTIONS: [&str; 26] = [
    "netfi", "frames", "dropped", "accounting", "loss", "phase", "delay", "overhead", "ingress", "decision", "release", "end-to-end",
    "direct", "emulator", "q0.5", "kinematics", "clutch", "feedback", "round", "emulator's", "live", "host", "peer", "files",
    "trace", "histogram",
];

/// The first word of each line: what sections the text has.
fn sections(text: &str) -> std::collections::BTreeSet<&str> {
    text.lines().filter_map(|l| l.split_whitespace().next()).collect()
}

#[test]
fn a_run_started_by_hand_is_reported_like_a_netfi_run() {
    let dir = copy_dir(the_foreign_run(), "foreign-text");
    let text = report_text(&dir);
    assert!(text.contains("frames     sent 1000  entered 1000  delivered 1000  received 1000  held at end 0\n"), "{text}");
    assert!(text.contains("accounting balanced"), "{text}");
    assert!(!text.contains("FAULT") && !text.contains("missing"), "{text}");
    // The delay law of the preset the emulator names, the run having no copy of its scenario.
    let law = text.lines().find(|l| l.starts_with("  q0.5 ")).unwrap_or_else(|| panic!("no delay law: {text}"));
    assert!(law.contains('['), "no model band: {law}");
    // The sections of a netfi run's report but those only its runner
    // knows (provenance, processes, isolation).
    let run = report_text(the_run());
    for (which, text) in [("netfi run", &run), ("run by hand", &text)] {
        let have = sections(text);
        let lacking: Vec<&&str> = SECTIONS.iter().filter(|s| !have.contains(*s)).collect();
        assert!(lacking.is_empty(), "{which}: sections missing: {lacking:?}\n{text}");
    }
    // The emulator's trace is joined with the robot's receipts, and kept:
    // the report can be made again, the same.
    let trace = std::fs::read_to_string(dir.join("trace.csv")).unwrap();
    assert_eq!(trace.lines().skip(1).filter(|l| !l.contains(",delivered,") || l.ends_with(',')).count(), 0, "a row without its receipt");
    assert!(dir.join("trace_emulator.csv").exists());
    assert_eq!(report_text(&dir), text);
    // The emulator's report says the forward frames balance.
    let e: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("emulator.json")).unwrap()).unwrap();
    assert_eq!(e["frames"]["balanced"], true, "{}", e["frames"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_run_of_foreign_clients_says_what_is_missing_and_names_cut_files() {
    let dir = copy_dir(the_foreign_run(), "foreign-missing");
    // Foreign clients write no console.json or simulator.json; a writer
    // stopped early leaves its file as NAME.partial.
    for f in ["console.json", "simulator.json", "end_to_end.hlog", "direct_hop.hlog"] {
        std::fs::remove_file(dir.join(f)).unwrap();
    }
    std::fs::rename(dir.join("received.csv"), dir.join("received.csv.partial")).unwrap();
    // A cut file is a fault: the text report says so and fails.
    let o = netfi().arg("report").arg(&dir).output().unwrap();
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(!o.status.success(), "a run with a cut file reported as whole:\n{text}");
    let cut = dir.join("received.csv.partial");
    assert!(String::from_utf8_lossy(&o.stderr).contains(&format!("cut file: {}", cut.display())), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("missing    console.json, simulator.json (what needs them is shown as ?)\n"), "{text}");
    assert!(text.contains("frames     sent 1000  entered 1000  delivered 1000  received ?  held at end 0\n"), "{text}");
    assert!(text.contains("accounting balanced at the emulator: ") && text.contains("not known: what the robot received"), "{text}");
    assert!(text.contains(&format!("FAULT      cut file: {}", cut.display())), "{text}");
    // The cut receipts are still read: the seen delays are there.
    assert!(text.lines().any(|l| l.starts_with("  q0.5 ")), "{text}");
    let o = netfi().arg("report").arg(&dir).arg("--html").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(text_of(&html, "missing").contains("console.json, simulator.json"), "{}", text_of(&html, "missing"));
    assert!(html.contains(&cut.display().to_string()));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_page_of_a_run_started_by_hand_has_its_figures() {
    let dir = copy_dir(the_foreign_run(), "foreign-html");
    let o = netfi().arg("report").arg(&dir).arg("--html").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let e: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("emulator.json")).unwrap()).unwrap();
    let at = html.find("id=\"realized-loss\"").unwrap();
    let value: f64 = html[at..].split("data-value=\"").nth(1).unwrap().split('"').next().unwrap().parse().unwrap();
    assert_eq!(value, e["loss_rate"].as_f64().unwrap());
    assert_eq!(text_of(&html, "balanced"), "balanced");
    assert_eq!(polylines(svg(&html, "plot-latency")).len(), 4, "every latency series drawn");
    assert_eq!(polylines(svg(&html, "plot-delay-law")).len(), 3, "seen, drawn and the preset's law");
    assert!(!html.contains("id=\"missing\""));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_directory_of_no_run_is_an_error_naming_what_would_do() {
    let dir = temp_dir("no-run");
    std::fs::create_dir_all(&dir).unwrap();
    for html in [false, true] {
        let mut c = netfi();
        c.arg("report").arg(&dir);
        if html {
            c.arg("--html");
        }
        let o = c.output().unwrap();
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        for f in ["report.json", "emulator.json"] {
            assert!(err.contains(&dir.join(f).display().to_string()), "{f}: {err}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A valid ITP frame with sequence `seq`.
fn itp(seq: u32) -> [u8; 124] {
    let mut b = [0u8; 124];
    let mut v = netfi::frame::ItpView::new_unchecked(&mut b[..]);
    v.set_sequence(seq);
    v.set_delx([(seq % 7) as i32, 1]);
    v.set_qw([1.0, 1.0]);
    v.set_surgeon_mode(1);
    v.fill_checksum();
    b
}

/// A UDP run: the emulator between two sockets this test holds, as a
/// console and a robot of another make would (docs/udp.md); no process
/// writes a report but the emulator.
#[test]
fn a_udp_run_started_by_hand_is_reported_with_its_sockets() {
    use std::net::UdpSocket;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let _guard = machine::alone();
    let dir = temp_dir("foreign-udp");
    let console = UdpSocket::bind("127.0.0.1:0").unwrap();
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    robot.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
    let robot_addr = robot.local_addr().unwrap();
    let ingress = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let emulator = service("emulator")
        .args(["--scenario", "PLM-2", "--seed", "5", "--expected-frames", "500", "--idle-end-ms", "1000", "--no-pin"])
        .args(["--ingress", &format!("udp://{ingress}"), "--egress", &format!("udp://{robot_addr}")])
        .args(["--console-from", &console.local_addr().unwrap().to_string(), "--out"])
        .arg(&dir)
        .spawn()
        .unwrap();
    crate::common::wait_file(&dir.join("emulator.ready"));
    let done = Arc::new(AtomicBool::new(false));
    let receiving = {
        let done = done.clone();
        std::thread::spawn(move || {
            let (mut n, mut buf) = (0u64, [0u8; 256]);
            while !done.load(Ordering::Relaxed) {
                n += u64::from(robot.recv(&mut buf).is_ok());
            }
            n
        })
    };
    for seq in 0..500 {
        console.send_to(&itp(seq), ingress).unwrap();
        // Paced, so that no socket buffer overflows on a loaded host.
        if seq % 20 == 19 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    finish(emulator, "emulator");
    done.store(true, Ordering::Relaxed);
    let received = receiving.join().unwrap();
    let text = report_text(&dir);
    let e: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("emulator.json")).unwrap()).unwrap();
    let delivered = e["frames"]["delivered"].as_u64().unwrap();
    assert_eq!(received, delivered, "the robot got every frame released");
    assert!(text.contains(&format!("udp        ingress udp://{ingress} (bound {ingress}), egress udp://{robot_addr}")), "{text}");
    assert!(text.contains("500 datagrams in, 0 dropped by the kernel before ingress"), "{text}");
    assert!(text.contains(&format!("entered 500  delivered {delivered}  received ?")), "{text}");
    assert!(text.contains("missing    console.json, simulator.json"), "{text}");
    assert!(!text.contains("FAULT"), "{text}");
    let o = netfi().arg("report").arg(&dir).arg("--html").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(text_of(&html, "udp").contains("500 datagrams in"), "{}", text_of(&html, "udp"));
    std::fs::remove_dir_all(&dir).ok();
}
