//! Studies whose trials join the lab's own console and robot: programs of
//! the test's standing in for a lab's (a console and a robot written from
//! docs/interface.md over iceoryx2; UDP sockets), each trial started with
//! `netfi study next` as an experimenter would. The table's motion
//! figures are recomputed here from what those programs sent and
//! received; a console that never comes, or dies mid-trial, interrupts
//! the trial.

use super::{csv, status, study, study_output, wait_for, Scratch};
use crate::common::machine;
use crate::common::netfi::netfi;
use netfi::frame::ItpView;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// The table's value of `column` in row `row`.
fn cell<'a>(header: &[String], row: &'a [String], column: &str) -> &'a str {
    let i = header.iter().position(|h| h == column).unwrap_or_else(|| panic!("no column {column} in {header:?}"));
    &row[i]
}

fn number(header: &[String], row: &[String], column: &str) -> f64 {
    let v = cell(header, row, column);
    v.parse().unwrap_or_else(|_| panic!("{column} = `{v}` is not a number"))
}

/// The motion length per arm, mm, of ITP frames (as `wire` bytes), in
/// the order taken: each engaged frame's increment's length, 0.01 mm per
/// unit (docs/spec.md's kinematics).
fn motion_mm(frames: impl IntoIterator<Item = [u8; 124]>) -> [f64; 2] {
    let mut len = [0.0; 2];
    for f in frames {
        let v = ItpView::new_unchecked(&f[..]);
        if v.surgeon_mode() != 1 {
            continue;
        }
        let (x, y, z) = (v.delx(), v.dely(), v.delz());
        for arm in 0..2 {
            len[arm] += ((x[arm] as f64).powi(2) + (y[arm] as f64).powi(2) + (z[arm] as f64).powi(2)).sqrt() * 0.01;
        }
    }
    len
}

#[track_caller]
fn assert_close(what: &str, got: f64, want: f64) {
    assert!((got - want).abs() <= 1e-9 * want.abs().max(1.0), "{what}: the table says {got}, the test's programs give {want}");
}

/// A study of one participant with the lab's ends at `lab` (TOML lines of
/// `[trial.lab]`) and `trial` (more lines of `[trial]`), under `conditions`.
fn lab_study(dir: &Scratch, trial: &str, lab: &str, conditions: &[&str]) -> PathBuf {
    let list: Vec<String> = conditions.iter().map(|c| format!("\"{c}\"")).collect();
    dir.file(
        "study.toml",
        &format!(
            "name = \"lab\"\nseed = 5\ndata = \"data\"\n[trial]\nduration_s = 60\npeers = \"lab\"\n{trial}\n[trial.lab]\n{lab}\n\
             [questionnaires]\nsus = \"none\"\ntlx = \"none\"\n[[block]]\nname = \"b\"\nconditions = [{}]\n[[participant]]\nid = \"P1\"\n",
            list.join(", ")
        ),
    )
}

/// `netfi study next` started in the background.
fn next(file: &Path) -> Child {
    netfi().args(["study", "next", file.to_str().unwrap(), "-p", "P1"]).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
}

fn finished(child: Child) -> String {
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "netfi study next failed: {}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

/// Whom the running trial waits for, as `status` says.
fn waiting_for(file: &Path) -> Option<String> {
    let s = status(file, "P1");
    (s["next"]["kind"] == "running").then(|| s["next"]["waiting_for"].as_str().map(String::from)).flatten()
}

/// The study's `trials.csv` after `netfi study report`.
fn table(file: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let f = file.to_str().unwrap();
    let out = study(&["report", f]);
    csv(&std::fs::read_to_string(Path::new(out.trim()).join("trials.csv")).unwrap())
}

/// A UDP console and robot of the test's: each trial waits for the
/// console (and says so), the console sends 400 frames and falls silent
/// (the study's `idle-end-ms` ends the run), the robot takes what comes;
/// the table's console and robot motion are what they sent and received.
#[test]
fn a_study_over_udp_measures_the_lab_programs_streams() {
    let _one = machine::alone();
    let dir = Scratch::new("lab-udp");
    let robot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let console = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let ingress = std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let lab = format!(
        "ingress = \"udp://{ingress}\"\nconsole-from = \"{}\"\negress = \"udp://{}\"\nidle-end-ms = 1500\nno-return = true",
        console.local_addr().unwrap(),
        robot.local_addr().unwrap()
    );
    let file = lab_study(&dir, "", &lab, &["Normal", "PLM-2"]);
    robot.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    let mut sent_by_trial = Vec::new();
    let mut received_by_trial = Vec::new();
    for trial in 1..=2u32 {
        let child = next(&file);
        wait_for("the trial to wait for the lab's console", 60, || waiting_for(&file).is_some_and(|w| w.contains("console") && w.contains(&ingress.to_string())));
        let frames: Vec<[u8; 124]> = (0..400u32)
            .map(|s| {
                let mut b = [0u8; 124];
                let mut v = ItpView::new_unchecked(&mut b[..]);
                v.set_sequence(s);
                v.set_delx([(s % 7) as i32 + trial as i32, -1]);
                v.set_dely([2, (s % 5) as i32]);
                v.set_delz([0, 1]);
                v.set_qw([1.0, 1.0]);
                v.set_surgeon_mode(if s % 50 < 45 { 1 } else { 0 });
                v.fill_checksum();
                b
            })
            .collect();
        let stop = std::sync::atomic::AtomicBool::new(false);
        let got = std::thread::scope(|sc| {
            let rx = sc.spawn(|| {
                let mut got = Vec::new();
                let mut buf = [0u8; 2048];
                while !stop.load(std::sync::atomic::Ordering::Acquire) {
                    if let Ok(n) = robot.recv(&mut buf) {
                        got.push(<[u8; 124]>::try_from(&buf[..n]).expect("an ITP frame"));
                    }
                }
                got
            });
            for f in &frames {
                console.send_to(f, ingress).unwrap();
                std::thread::sleep(Duration::from_millis(1));
            }
            let out = finished(child);
            assert!(out.contains(": ran ("), "{out}");
            // Whatever was still on its way is in the robot's socket.
            std::thread::sleep(Duration::from_millis(300));
            stop.store(true, std::sync::atomic::Ordering::Release);
            rx.join().unwrap()
        });
        study(&["mark", file.to_str().unwrap(), "-p", "P1", "done"]);
        sent_by_trial.push(frames);
        received_by_trial.push(got);
    }
    let (header, rows) = table(&file);
    assert_eq!(rows.len(), 2);
    for (row, (sent, got)) in rows.iter().zip(sent_by_trial.iter().zip(&received_by_trial)) {
        assert_eq!(cell(&header, row, "outcome"), "done");
        let (c, r) = (motion_mm(sent.iter().copied()), motion_mm(got.iter().copied()));
        for arm in 0..2 {
            assert_close(&format!("console arm {arm}"), number(&header, row, &format!("console_motion_arm{arm}_mm")), c[arm]);
            assert_close(&format!("robot arm {arm}"), number(&header, row, &format!("robot_motion_arm{arm}_mm")), r[arm]);
        }
        assert_eq!(number(&header, row, "frames_sent") as usize, sent.len(), "{row:?}");
        // What the lab's robot received only it knows: not a figure of netfi's.
        assert_eq!(cell(&header, row, "frames_received"), "", "{row:?}");
        // Eight clutch releases and re-engagements in 400 frames.
        assert_eq!(number(&header, row, "clutch_activations"), 7.0);
        assert!(["clean", "suspect"].contains(&cell(&header, row, "clean")), "{row:?}");
        assert_eq!(cell(&header, row, "clean") == "suspect", !cell(&header, row, "suspect_because").is_empty());
        assert!(number(&header, row, "command_span_s") > 0.3, "{row:?}");
    }
    // PLM-2 lost frames on the way: the robot got fewer, and the table's
    // robot motion is what it got, not what was sent.
    assert!(received_by_trial.iter().any(|g| g.len() < 400));
}

/// A console that never comes: the trial waits `peer_wait_s`, saying whom
/// it waits for, and ends `interrupted` with the reason, never counted.
#[test]
fn a_lab_console_that_never_comes_interrupts_the_trial() {
    let _one = machine::alone();
    let dir = Scratch::new("lab-absent");
    let robot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let ingress = std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let lab = format!("ingress = \"udp://{ingress}\"\nconsole-from = \"first\"\negress = \"udp://{}\"", robot.local_addr().unwrap());
    let file = lab_study(&dir, "peer_wait_s = 2", &lab, &["Normal"]);
    let child = next(&file);
    wait_for("the trial to say it waits for the console", 60, || waiting_for(&file).is_some_and(|w| w.contains("the lab's console")));
    let out = finished(child);
    assert!(out.contains("interrupted"), "{out}");
    let s = status(&file, "P1");
    let t = &s["trials"][0];
    assert_eq!(t["state"], "interrupted", "{s:#}");
    assert!(t["note"].as_str().unwrap().contains("sent nothing"), "{t}");
    // Not counted: the same trial comes next again.
    assert_eq!(s["next"]["kind"], "trial");
    assert_eq!(s["next"]["trial"], 1);
    let marked = study_output(&["mark", file.to_str().unwrap(), "-p", "P1", "done", "--trial", "1"]);
    assert!(!marked.status.success());
}

/// The console and robot written from docs/interface.md alone
/// (tests/python/doc_client.py) join a study's trials over iceoryx2: each
/// finds the trial's run id in `DATA/running.json`; the trial waits for
/// the robot, then the console, saying so; the table's motion is what the
/// console sent and the robot received. Then a console killed mid-trial
/// interrupts its trial.
#[test]
fn a_study_over_iceoryx2_joins_a_console_and_robot_written_from_the_docs() {
    if !crate::python::python_ready() {
        return;
    }
    let _one = machine::alone();
    let dir = Scratch::new("lab-ipc");
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/python/doc_client.py");
    let file = lab_study(&dir, "", "", &["PLM-2"]);
    let data = file.parent().unwrap().join("data");
    let doc = |args: &[&str]| {
        let mut c = Command::new("python3");
        c.arg(&script).args(args).env_remove("PYTHONPATH").stdout(Stdio::null()).stderr(Stdio::piped());
        c
    };
    let run_id = || -> Option<String> {
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(data.join("running.json")).ok()?).ok()?;
        v["run_id"].as_str().map(String::from)
    };
    let child = next(&file);
    wait_for("the trial's run id in running.json", 60, || run_id().is_some());
    let run = run_id().unwrap();
    wait_for("the trial to wait for the lab's robot", 60, || waiting_for(&file).is_some_and(|w| w.contains("the lab's robot")));
    let path = |n: &str| dir.join(n).to_str().unwrap().to_string();
    let robot = doc(&["robot", &run, &path("robot.json"), &path("robot.ready")]).spawn().unwrap();
    wait_for("the trial to wait for the lab's console", 60, || waiting_for(&file).is_some_and(|w| w.contains("the lab's console")));
    let console = doc(&["console", &run, "600", &path("console.json")]).output().unwrap();
    assert!(console.status.success(), "{}", String::from_utf8_lossy(&console.stderr));
    let out = finished(child);
    assert!(out.contains(": ran ("), "{out}");
    let robot = robot.wait_with_output().unwrap();
    assert!(robot.status.success(), "{}", String::from_utf8_lossy(&robot.stderr));
    study(&["mark", file.to_str().unwrap(), "-p", "P1", "done"]);
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(path("robot.json")).unwrap()).unwrap();
    // The document's console's frames (doc_client.py `itp`).
    let itp = |s: u32| {
        let mut b = [0u8; 124];
        let mut v = ItpView::new_unchecked(&mut b[..]);
        v.set_sequence(s);
        v.set_delx([(s % 7) as i32, -1]);
        v.set_dely([2, (s % 5) as i32]);
        v.set_delz([0, 1]);
        v.set_surgeon_mode(1);
        b
    };
    let received: Vec<u32> = r["sequences"].as_array().unwrap().iter().map(|s| s.as_u64().unwrap() as u32).collect();
    let (c, rb) = (motion_mm((0..600).map(itp)), motion_mm(received.iter().map(|&s| itp(s))));
    let (header, rows) = table(&file);
    let row = &rows[0];
    for arm in 0..2 {
        assert_close(&format!("console arm {arm}"), number(&header, row, &format!("console_motion_arm{arm}_mm")), c[arm]);
        assert_close(&format!("robot arm {arm}"), number(&header, row, &format!("robot_motion_arm{arm}_mm")), rb[arm]);
    }
    assert!(received.len() < 600, "PLM-2 dropped none of 600");

    // A second study, whose console is killed mid-trial: the trial is
    // interrupted, naming the dead peer.
    let dir2 = Scratch::new("lab-ipc-killed");
    let file2 = lab_study(&dir2, "", "", &["Normal"]);
    let data2 = file2.parent().unwrap().join("data");
    let child = next(&file2);
    let run_id2 = || -> Option<String> {
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(data2.join("running.json")).ok()?).ok()?;
        v["run_id"].as_str().map(String::from)
    };
    wait_for("the second study's run id", 60, || run_id2().is_some());
    let run = run_id2().unwrap();
    let mut robot = doc(&["robot", &run, &path("robot2.json"), &path("robot2.ready")]).spawn().unwrap();
    wait_for("the trial to wait for the lab's console", 60, || waiting_for(&file2).is_some_and(|w| w.contains("the lab's console")));
    let mut console = doc(&["console", &run, "60000", &path("console2.json")]).spawn().unwrap();
    wait_for("the console's frames to flow", 60, || waiting_for(&file2).is_none());
    console.kill().unwrap();
    console.wait().unwrap();
    let out = finished(child);
    assert!(out.contains("interrupted"), "{out}");
    let s = status(&file2, "P1");
    assert_eq!(s["trials"][0]["state"], "interrupted", "{s:#}");
    assert!(s["trials"][0]["note"].as_str().unwrap().contains("peer died"), "{}", s["trials"][0]);
    let _ = robot.kill();
    let _ = robot.wait();
}
