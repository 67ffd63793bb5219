//! Only the intended peers over UDP: the console's address is fixed (the
//! first sender's, locked, or `--console-from`); datagrams from any other
//! socket are dropped before they enter, counted as `foreign_sender` with
//! their senders named, and never take over the return path.

use crate::bridge::{itp, out_dir, read_json, receiver, send_paced, socket, u, Emulator};
use crate::ONE_RUN_AT_A_TIME;
use netfi::frame::ItpView;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

fn frames(seqs: std::ops::Range<u32>) -> Vec<Vec<u8>> {
    seqs.map(|s| itp(s).to_vec()).collect()
}

/// One run: the intruder sends `intruder_first` frames before the console
/// starts and 50 more in the middle of the console's 200; `console_from`
/// fixes the console's address. Checks what the robot, the console and the
/// intruder got, and the report.
fn run(name: &str, intruder_first: u32, console_from: bool) {
    let _guard = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let out = out_dir(name);
    let robot = socket();
    let console = socket();
    let intruder = socket();
    let egress = format!("udp://{}", robot.local_addr());
    let from = console.local_addr().to_string();
    let mut args = vec!["--scenario", "Normal", "--seed", "1", "--ingress", "udp://127.0.0.1:0", "--egress", &egress, "--idle-end-ms", "1000"];
    if console_from {
        args.extend(["--console-from", &from]);
    }
    let emu = Emulator::start(&out, &args);
    let feedback: Vec<u8> = (0..52u8).collect();
    let stop = Arc::new(AtomicBool::new(false));
    let robot_rx = receiver(robot, stop.clone(), Some(feedback.clone()));
    let console_rx = receiver(console.try_clone().unwrap(), stop.clone(), None);
    let intruder_rx = receiver(intruder.try_clone().unwrap(), stop.clone(), None);
    let mut foreign = send_paced(&intruder, emu.ingress(), frames(5000..5000 + intruder_first), 10);
    let mut sent = send_paced(&console, emu.ingress(), frames(0..100), 10);
    foreign += send_paced(&intruder, emu.ingress(), frames(6000..6050), 10);
    sent += send_paced(&console, emu.ingress(), frames(100..200), 10);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, _) = robot_rx.join().unwrap();
    let (back, _) = console_rx.join().unwrap();
    let (stolen, _) = intruder_rx.join().unwrap();

    let kernel = u(&udp["ingress_kernel_drops"]);
    assert_eq!(kernel, 0, "paced sends on loopback: {udp}");
    // The robot got the console's frames only, in order.
    let seqs: Vec<u32> = got.iter().map(|d| ItpView::new_unchecked(&d[..]).sequence()).collect();
    assert_eq!(seqs, (0..200).collect::<Vec<_>>(), "the robot got only the console's frames");
    // The robot's replies all went to the console, none to the intruder.
    assert_eq!(back.len() as u64, sent, "the console got every reply");
    assert!(stolen.is_empty(), "the intruder got {} replies", stolen.len());
    // The accounting: the console's frames entered; the intruder's were
    // counted apart, with the intruder named.
    assert_eq!(u(&e["frames"]["entered"]), sent, "{}", e["frames"]);
    assert_eq!(u(&e["frames"]["delivered"]), sent);
    assert_eq!(u(&udp["datagrams_in"]), sent);
    assert_eq!(u(&udp["foreign_sender"]), foreign, "{udp:#}");
    assert_eq!(udp["console"], console.local_addr().to_string());
    let named = udp["foreign_senders"].as_array().unwrap();
    assert_eq!(named.len(), 1, "{udp:#}");
    assert_eq!(named[0]["addr"], intruder.local_addr().to_string());
    assert_eq!(u(&named[0]["datagrams"]), foreign);
    assert_eq!(u(&udp["return_path"]["delivered"]), sent, "{:#}", udp["return_path"]);
    let _ = read_json(&out.join("udp_endpoints.json"));
}

#[test]
fn an_intruder_after_the_first_sender_is_dropped_and_gets_no_replies() {
    run("foreign-locked", 0, false);
}

#[test]
fn with_console_from_an_intruder_that_speaks_first_is_dropped() {
    run("foreign-given", 30, true);
}
