use super::table::Table;
use super::*;
use crate::injector::DropCause;
use crate::model::ModelKind;
use std::io::Write;
use std::path::PathBuf;

fn ingress(i: u64, seq: Option<u32>, send: u64, at: u64, dropped: Option<DropCause>, sched: u64) -> TraceEvent {
    TraceEvent::Ingress { ingress_index: i, sequence: seq, console_index: i, send_ns: send, ingress_ns: at, dropped, release_sched_ns: sched, decision_ns: 50, copies: 0, copies_dropped: 0, corrupted: false }
}

/// The row format as it was written with `write!` (one `String` per
/// optional field): the reference the allocation-free [`format_row`]
/// must match byte for byte.
fn format_row_reference(i: u64, r: &Row, copy: Option<&CopyRow>, recv: Option<u64>) -> String {
    let (dropped, sched, released, corrupted) = match copy {
        None => (r.dropped, r.release_sched_ns, r.release_ns, r.corrupted),
        Some(c) => (None, c.release_sched_ns, c.release_ns, c.corrupted),
    };
    let (fate, reason, phase, stage) = match dropped {
        None if released.is_some() => ("delivered", "", String::new(), String::new()),
        None => ("held", "", String::new(), String::new()),
        Some(c) => {
            let (p, s) = match c {
                DropCause::Stage { phase, stage, .. } => ((phase + 1).to_string(), (stage + 1).to_string()),
                _ => (String::new(), String::new()),
            };
            ("dropped", c.reason(), p, s)
        }
    };
    let opt = |v: Option<u64>| v.map(|x| x.to_string()).unwrap_or_default();
    let scheduled = dropped.is_none();
    let (copy_no, copies_dropped) = match copy {
        None => (0, Some(u64::from(r.copies_dropped))),
        Some(c) => (c.copy, None),
    };
    format!(
        "{i},{},{},{},{},{fate},{reason},{phase},{stage},{},{},{},{},{copy_no},{},{}\n",
        r.sequence.map(|s| s.to_string()).unwrap_or_default(),
        r.console_index,
        r.send_ns,
        r.ingress_ns,
        opt(scheduled.then(|| sched.saturating_sub(r.ingress_ns))),
        opt(scheduled.then_some(sched)),
        opt(released),
        opt(recv),
        opt(copies_dropped),
        opt(scheduled.then_some(u64::from(corrupted))),
    )
}

#[test]
fn rows_are_formatted_as_before_byte_for_byte() {
    let causes = [
        None,
        Some(DropCause::Stage { phase: 0, stage: 0, kind: ModelKind::GeLomax }),
        Some(DropCause::Stage { phase: 7, stage: 300, kind: ModelKind::Rate }),
        Some(DropCause::QueueFull),
        Some(DropCause::Invalid(crate::injector::Invalid::BadChecksum)),
    ];
    let (big, mut n) = (u64::MAX, 0);
    for dropped in causes {
        for released in [None, Some(0), Some(big)] {
            for sequence in [None, Some(0), Some(u32::MAX)] {
                for (sched, ingress) in [(0, 0), (5, 9), (big, 1), (big, big)] {
                    let r = Row { present: true, sequence, console_index: big - 1, send_ns: 3, ingress_ns: ingress, dropped, release_sched_ns: sched, release_ns: released, copies_pending: 0, copies_dropped: 255, corrupted: sched % 2 == 1 };
                    let copies = [None, Some(CopyRow { ingress_index: 1, copy: 255, release_sched_ns: sched, release_ns: released, corrupted: true })];
                    for copy in copies {
                        for recv in [None, Some(big)] {
                            let mut got = Vec::new();
                            format_row(&mut got, big, &r, copy.as_ref(), recv).unwrap();
                            assert_eq!(String::from_utf8(got).unwrap(), format_row_reference(big, &r, copy.as_ref(), recv));
                            n += 1;
                        }
                    }
                }
            }
        }
    }
    assert_eq!(n, 5 * 3 * 3 * 4 * 2 * 2);
}

#[test]
fn events_become_rows_in_ingress_order_as_they_complete() {
    let dir = std::env::temp_dir().join(format!("netfi-trace-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("trace.csv");
    let (mut sink, mut writer) = start(4, 0);
    writer.stream_to(&path, Some(&dir)).unwrap();
    sink.push(ingress(0, Some(7), 10, 20, None, 120));
    let ge = DropCause::Stage { phase: 0, stage: 1, kind: ModelKind::GeLomax };
    sink.push(ingress(1, Some(8), 30, 40, Some(ge), 0));
    // Row 1 is complete but row 0 is not: nothing is written yet. Until
    // the end the file says it is not whole.
    let partial = crate::durable::partial_path(&path);
    std::thread::sleep(std::time::Duration::from_millis(1200));
    let text = std::fs::read_to_string(&partial).unwrap();
    assert_eq!(text.lines().count(), 1, "{text}");
    sink.push(TraceEvent::Release { ingress_index: 0, release_sched_ns: 120, release_ns: 121 });
    // Within the flush period both are on disk, before the end.
    std::thread::sleep(std::time::Duration::from_millis(1200));
    let text = std::fs::read_to_string(&partial).unwrap();
    assert_eq!(text.lines().count(), 3, "{text}");
    assert!(!path.exists() && !dir.join("decision.hlog").exists());
    sink.push(ingress(2, None, 50, 60, None, 70));
    let w = writer.finish(&path).unwrap();
    assert!(!partial.exists() && crate::durable::cut_files(&dir).unwrap().is_empty(), "whole files under their own names");
    assert_eq!((w.rows, w.forced), (3, 0));
    assert!(w.intervals >= 2);
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<_> = text.lines().collect();
    assert_eq!(lines[1], "0,7,0,10,20,delivered,,,,100,120,121,,0,0,0");
    assert_eq!(lines[2], "1,8,1,30,40,dropped,ge_lomax,1,2,,,,,0,0,");
    assert_eq!(lines[3], "2,,2,50,60,held,,,,10,70,,,0,0,0");
    assert_eq!(sink.overflowed(), 0);
    // One interval per flush in each histogram log, tagged.
    for (file, tag) in [("decision.hlog", "decision"), ("lateness.hlog", "release_lateness")] {
        let log = std::fs::read(dir.join(file)).unwrap();
        let tags: Vec<String> = hdrhistogram::serialization::interval_log::IntervalLogIterator::new(&log)
            .filter_map(|e| match e {
                Ok(hdrhistogram::serialization::interval_log::LogEntry::Interval(i)) => i.tag().map(|t| t.as_str().to_string()),
                _ => None,
            })
            .collect();
        assert_eq!(tags.len() as u64, w.intervals, "{file}");
        assert!(tags.iter().all(|t| t == tag), "{tags:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_csv_log_streams_its_rows_and_is_whole_once_finished() {
    let path = std::env::temp_dir().join(format!("netfi-csvlog-{}.csv", std::process::id()));
    let partial = crate::durable::partial_path(&path);
    let mut log = CsvLog::create(path.clone(), "a,b").unwrap();
    log.push(|w| writeln!(w, "1,2"));
    // Not yet a second since the last flush (none: at 0): nothing asked.
    log.tick(1);
    log.tick(FLUSH_EVERY.as_nanos() as u64);
    // Flushed while the log is still open: a killed process keeps it,
    // under the name that says it is cut.
    assert_eq!(std::fs::read_to_string(&partial).unwrap(), "a,b\n1,2\n");
    assert!(!path.exists());
    log.push(|w| writeln!(w, "3,4"));
    assert_eq!(log.rows(), 2);
    assert_eq!(log.finish().unwrap(), path);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,b\n1,2\n3,4\n");
    assert!(!partial.exists());
    std::fs::remove_file(&path).ok();
}

/// A tmpfs of `size` mounted at a fresh directory, unmounted and
/// removed when dropped; `None` (the test then says so and passes)
/// where this process may not mount, unless `NETFI_REQUIRE_ROOT=1`
/// demands it (`.ci/run` runs as root).
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(name: &str, size: &str) -> Option<Tmpfs> {
        let dir = std::env::temp_dir().join(format!("netfi-tmpfs-{}-{name}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let mounted = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&dir)
            .stderr(std::process::Stdio::piped())
            .output();
        match mounted {
            Ok(o) if o.status.success() => Some(Tmpfs(dir)),
            other => {
                let why = match other {
                    Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_string(),
                    Err(e) => e.to_string(),
                };
                let _ = std::fs::remove_dir(&dir);
                assert!(std::env::var("NETFI_REQUIRE_ROOT").as_deref() != Ok("1"), "NETFI_REQUIRE_ROOT=1 but a tmpfs cannot be mounted: {why}");
                eprintln!("SKIP: cannot mount a tmpfs here ({why}; not root?): the full-disk test did not run");
                None
            }
        }
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

#[test]
fn a_full_disk_leaves_every_file_it_cut_marked_and_named() {
    let Some(fs) = Tmpfs::mount("full", "64k") else { return };
    let dir = fs.0.clone();
    // The trace: 4,000 rows of about 60 bytes do not fit in 64 KiB.
    let (mut sink, mut writer) = start(4000, 0);
    writer.stream_to(&dir.join("trace_emulator.csv"), Some(&dir)).unwrap();
    let ge = DropCause::Stage { phase: 0, stage: 0, kind: ModelKind::GeLomax };
    for i in 0..4000 {
        sink.push(ingress(i, Some(i as u32), 1_000_000_000 + i, 2_000_000_000 + i, Some(ge), 0));
    }
    assert_eq!(sink.overflowed(), 0);
    let e = format!("{:#}", writer.finish(&dir.join("trace_emulator.csv")).unwrap_err());
    assert!(e.contains("trace_emulator.csv.partial") && e.contains("No space left on device"), "{e}");
    assert!(!dir.join("trace_emulator.csv").exists(), "a cut trace is not under its own name");
    // A CSV log on the full disk: its rows cannot be flushed.
    let mut log = CsvLog::create(dir.join("received.csv"), "ingress_index,recv_ns").unwrap();
    for i in 0..2000u64 {
        log.push(|w| writeln!(w, "{i},{}", 3_000_000_000 + i));
    }
    let e = format!("{:#}", log.finish().unwrap_err());
    assert!(e.contains("received.csv.partial") && e.contains("No space left on device"), "{e}");
    // A JSON report written whole, or not at all under its name.
    let e = crate::durable::write_whole(&dir.join("report.json"), &vec![b' '; 1 << 16]).unwrap_err();
    assert!(e.to_string().contains("report.json.partial"), "{e}");
    assert!(!dir.join("report.json").exists());
    // The run's cut files, every one named.
    let names: Vec<String> = crate::durable::cut_files(&dir)
        .unwrap()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for cut in ["trace_emulator.csv.partial", "decision.hlog.partial", "lateness.hlog.partial", "received.csv.partial", "report.json.partial"] {
        assert!(names.iter().any(|n| n == cut), "{cut} not among the cut files {names:?}");
    }
    // What was written before the disk filled is there to read.
    let kept = std::fs::read_to_string(dir.join("trace_emulator.csv.partial")).unwrap();
    assert!(kept.starts_with(CSV_HEADER) && kept.lines().count() > 100, "{} bytes kept", kept.len());
}

#[test]
fn write_csv_joins_receive_times() {
    let rows = [Row { present: true, sequence: Some(1), console_index: 0, send_ns: 1, ingress_ns: 2, dropped: None, release_sched_ns: 3, release_ns: Some(4), ..Row::default() }];
    let path = std::env::temp_dir().join(format!("netfi-trace-join-{}.csv", std::process::id()));
    write_csv(&path, &rows, &[9]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(text.lines().nth(1), Some("0,1,0,1,2,delivered,,,,1,3,4,9,0,0,0"));
}

#[test]
fn copies_get_rows_of_their_own_matched_by_scheduled_release() {
    let mut t = Table::with_capacity(0, 0, std::sync::mpsc::channel().1);
    // Frame 0: scheduled for 100, corrupted; two copies taken (for 300
    // and 200, the second corrupted) and one dropped.
    let mut ev = ingress(0, Some(5), 1, 10, None, 100);
    if let TraceEvent::Ingress { copies, copies_dropped, corrupted, .. } = &mut ev {
        (*copies, *copies_dropped, *corrupted) = (2, 1, true);
    }
    t.apply(ev);
    t.apply(TraceEvent::Copy { ingress_index: 0, copy: 1, release_sched_ns: 300, corrupted: false });
    t.apply(TraceEvent::Copy { ingress_index: 0, copy: 2, release_sched_ns: 200, corrupted: true });
    // Frame 1: dropped, but its one copy is taken.
    let ge = DropCause::Stage { phase: 0, stage: 2, kind: ModelKind::Bernoulli };
    let mut ev = ingress(1, Some(6), 20, 30, Some(ge), 0);
    if let TraceEvent::Ingress { copies, .. } = &mut ev {
        *copies = 1;
    }
    t.apply(ev);
    t.apply(TraceEvent::Copy { ingress_index: 1, copy: 1, release_sched_ns: 130, corrupted: false });
    let write = |t: &mut Table, all| {
        let mut out = Vec::new();
        t.drain(all, |i, r, c, _| format_row(&mut out, i, r, c, None).unwrap());
        out
    };
    t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 100, release_ns: 101 });
    t.apply(TraceEvent::Release { ingress_index: 1, release_sched_ns: 130, release_ns: 131 });
    t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 200, release_ns: 202 });
    assert!(write(&mut t, false).is_empty(), "frame 0 still has a copy queued");
    t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 300, release_ns: 303 });
    let out = write(&mut t, false);
    let text = String::from_utf8(out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines,
        [
            "0,5,0,1,10,delivered,,,,90,100,101,,0,1,1",
            "0,5,0,1,10,delivered,,,,290,300,303,,1,,0",
            "0,5,0,1,10,delivered,,,,190,200,202,,2,,1",
            "1,6,1,20,30,dropped,bernoulli,1,3,,,,,0,0,",
            "1,6,1,20,30,delivered,,,,100,130,131,,1,,0",
        ]
    );
    assert!(t.rows.is_empty() && t.copies.is_empty());
}
