//! No process of a run outlives its owner, and nothing of a dead run stays
//! in shared memory. These need no root: the processes are this test's
//! own (this binary re-run as a child, see [`child_process_entry`]).

use super::*;
use std::io::{BufRead, BufReader};
use std::process::{Child, ChildStdout, Stdio};

/// Environment variable that turns this binary into a child process.
const CHILD_ENV: &str = "NETFI_HOST_TEST_CHILD";

/// Not a test: the body of the child processes, by `NETFI_HOST_TEST_CHILD`.
///
/// - `die_with_parent:<pid>`: ties itself to parent `<pid>`, prints `READY`,
///   waits to be ended;
/// - `middle`: starts a `die_with_parent` child of its own, prints `CHILD
///   <pid>`, waits to be killed;
/// - `owner:<run>`: a run's owner: starts a guardian, two members (one that
///   ends on SIGTERM, one that ignores it), prints `RUN <guardian> <record>
///   <member> <member>`, waits to be killed.
#[test]
fn child_process_entry() {
    let Ok(spec) = std::env::var(CHILD_ENV) else { return };
    let (mode, arg) = spec.split_once(':').unwrap_or((&spec, ""));
    match mode {
        "die_with_parent" => {
            netfi::host::process::die_with_parent(arg.parse().unwrap()).unwrap();
            println!("READY");
        }
        "middle" => {
            let mut child = Peer::spawn(&format!("die_with_parent:{}", std::process::id()));
            child.expect("READY");
            println!("CHILD {}", child.pid());
            // Not reaped: this process is killed while it waits.
            std::mem::forget(child);
        }
        "owner" => {
            let mut guard = netfi::host::guardian::RunGuard::start(&[arg]).unwrap();
            let polite = Command::new("sleep").arg("120").spawn().unwrap();
            let mut deaf = Command::new("sh").args(["-c", "trap '' TERM; echo; while :; do sleep 0.1; done"]).stdout(Stdio::piped()).spawn().unwrap();
            // The shell's first line says its trap is set.
            BufReader::new(deaf.stdout.take().unwrap()).read_line(&mut String::new()).unwrap();
            guard.add(polite.id()).unwrap();
            guard.add(deaf.id()).unwrap();
            println!("RUN {} {} {} {}", guard.guardian_pid().unwrap(), guard.path().display(), polite.id(), deaf.id());
            std::mem::forget(guard);
        }
        other => panic!("unknown child mode {other}"),
    }
    loop {
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// A child running [`child_process_entry`], and its stdout; killed and
/// reaped however the test ends.
struct Peer {
    child: Child,
    stdout: BufReader<ChildStdout>,
}

impl Peer {
    fn spawn(mode: &str) -> Peer {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .arg(crate::common::test_name(module_path!(), "child_process_entry"))
            .args(["--exact", "--nocapture", "--test-threads=1"])
            .env(CHILD_ENV, mode)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = BufReader::new(child.stdout.take().unwrap());
        Peer { child, stdout }
    }

    fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    /// The rest of the first line that starts with `word` (libtest prints
    /// the test's name first, without a newline).
    fn expect(&mut self, word: &str) -> String {
        let mut line = String::new();
        loop {
            line.clear();
            assert!(self.stdout.read_line(&mut line).unwrap() > 0, "the child ended before saying {word}");
            if let Some(i) = line.find(word) {
                return line[i + word.len()..].trim().to_string();
            }
        }
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A run's owner as [`child_process_entry`] starts it.
struct OwnedRun {
    owner: Peer,
    guardian: i32,
    record: PathBuf,
    members: [i32; 2],
}

impl OwnedRun {
    fn start(tag: &str) -> OwnedRun {
        let mut owner = Peer::spawn(&format!("owner:{tag}{}", std::process::id()));
        let said = owner.expect("RUN ");
        let f: Vec<&str> = said.split(' ').collect();
        let run = OwnedRun {
            guardian: f[0].parse().unwrap(),
            record: PathBuf::from(f[1]),
            members: [f[2].parse().unwrap(), f[3].parse().unwrap()],
            owner,
        };
        assert!(run.record.exists() && alive(run.guardian) && run.members.iter().all(|&m| alive(m)));
        run
    }
}

impl Drop for OwnedRun {
    fn drop(&mut self) {
        self.members.iter().chain([&self.guardian]).filter(|&&p| alive(p)).for_each(|&p| sigkill(p));
        let _ = std::fs::remove_file(&self.record);
    }
}

#[test]
fn a_child_dies_with_its_parent() {
    let mut middle = Peer::spawn("middle");
    let child: i32 = middle.expect("CHILD ").parse().unwrap();
    assert!(alive(child));
    sigkill(middle.pid());
    wait_for("the child to end with its parent", Duration::from_secs(10), || !alive(child));
}

#[test]
fn a_child_whose_parent_is_already_gone_exits_at_once() {
    // Pid 1 is not this test's pid: the child finds its parent "gone".
    let mut peer = Peer::spawn("die_with_parent:1");
    let status = peer.child.wait().unwrap();
    assert_eq!(status.code(), Some(netfi::host::process::PARENT_GONE_EXIT));
}

/// Its owner killed, a run's other processes are ended by the guardian (the
/// one ignoring SIGTERM killed), the record removed, the guardian gone.
#[test]
fn the_guardian_ends_a_run_whose_owner_was_killed() {
    // The guardian also restores orphaned clearings: not during a kill case.
    let _guard = machine::alone();
    let run = OwnedRun::start("guarded");
    sigkill(run.owner.pid());
    wait_for("the run's processes to be ended", Duration::from_secs(10), || run.members.iter().all(|&m| !alive(m)));
    wait_for("the record to be removed", Duration::from_secs(10), || !run.record.exists());
    wait_for("the guardian to end", Duration::from_secs(10), || !alive(run.guardian));
}

/// Owner and guardian killed: the members run on (they are no children
/// that die with their parent) until `netfi restore` ends them.
#[test]
fn netfi_restore_ends_a_run_whose_owner_and_guardian_were_killed() {
    let _guard = machine::alone();
    let run = OwnedRun::start("unguarded");
    sigkill(run.guardian);
    sigkill(run.owner.pid());
    wait_for("the guardian to end", Duration::from_secs(10), || !alive(run.guardian));
    std::thread::sleep(Duration::from_millis(300));
    assert!(run.members.iter().all(|&m| alive(m)), "nothing should have ended the members yet");
    let said = restore();
    assert!(said.contains("ended what was left of a run whose owner is gone: 2 process(es) terminated, 1 of them killed"), "{said}");
    assert!(run.members.iter().all(|&m| !alive(m)));
    assert!(!run.record.exists());
}

/// What a run whose processes were all killed left in `/dev/shm` and
/// iceoryx2's directory goes with `netfi restore`, also what iceoryx2
/// cannot see (a half-created node, a segment of no node); a live run's
/// files stay.
#[test]
fn netfi_restore_removes_a_dead_runs_shared_memory_only() {
    let _guard = machine::alone();
    let run_id = format!("shmleft{}", std::process::id());
    let out = out_dir("shmleft");
    std::fs::create_dir_all(&out).unwrap();
    let runner = Reaped(
        netfi()
            .args(["run", "Normal", "--duration-s", "60", "--seed", "6", "--no-isolate", "--run-id", &run_id, "--out"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(out.join("runner.stderr")).unwrap())
            .spawn()
            .unwrap(),
    );
    let mut pids = Vec::new();
    wait_for("the run's processes", Duration::from_secs(60), || {
        pids = ["console", "emulator", "simulator"].iter().filter_map(|r| read_pid(&out, r)).collect();
        pids.len() == 3
    });
    // Leftovers iceoryx2 cannot see, from long ago.
    let prefix = format!("netfi_u{}_{run_id}_", uid());
    let node_dir = netfi::transport::ipc::user_root_dir().join("nodes").join("4242424242424242");
    std::fs::create_dir_all(&node_dir).unwrap();
    let planted = [node_dir.join(format!("{prefix}node.details")), PathBuf::from(format!("/dev/shm/{prefix}{}_1.data", "0".repeat(40)))];
    let long_ago = std::time::SystemTime::now() - Duration::from_secs(3600);
    for p in &planted {
        let f = std::fs::File::create(p).unwrap();
        f.set_times(std::fs::FileTimes::new().set_modified(long_ago)).unwrap();
    }
    // Alive: nothing of it is touched.
    restore();
    let missing: Vec<&PathBuf> = planted.iter().filter(|p| !p.exists()).collect();
    assert!(missing.is_empty(), "`netfi restore` removed files of a live run: {missing:?}");

    // Every process of the run killed, the run's guardian first.
    for g in guardians_of_run(runner.0.id() as i32) {
        sigkill(g);
    }
    pids.iter().chain([&(runner.0.id() as i32)]).for_each(|&p| sigkill(p));
    wait_for("the run's processes to end", Duration::from_secs(10), || pids.iter().all(|&p| !alive(p)));
    drop(runner);
    let said = restore();
    let left = ipc_files_of(&run_id);
    let _ = std::fs::remove_dir_all(&node_dir);
    planted.iter().for_each(|p| drop(std::fs::remove_file(p)));
    let _ = std::fs::remove_dir_all(&out);
    assert!(left.is_empty(), "left after `netfi restore`: {left:?}\n{said}");
    assert!(said.contains(&format!("of the dead run {run_id}")), "{said}");
}

/// The guardians watching the run of runner `pid` (`run-<pid>-….json`).
pub(crate) fn guardians_of_run(pid: i32) -> Vec<i32> {
    let want = format!("/run-{pid}-");
    std::fs::read_dir("/proc")
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<i32>().ok())
        .filter(|p| {
            std::fs::read(format!("/proc/{p}/cmdline")).is_ok_and(|c| {
                let c = String::from_utf8_lossy(&c);
                c.contains("restore\0--guard\0") && c.contains(&want)
            })
        })
        .collect()
}
