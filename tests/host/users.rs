//! iceoryx2's files: nothing left in `/dev/shm` after a run, nothing
//! another user can write, several users side by side.

use super::*;
use std::os::unix::fs::MetadataExt;

const NOBODY: u32 = 65534;

fn shm_with(needle: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|rd| rd.filter_map(|e| e.ok()?.file_name().into_string().ok()).filter(|n| n.contains(needle)).collect())
        .unwrap_or_default()
}

/// The netfi binary where the user nobody may run it: the build's own
/// path may pass through a directory only its owner can enter (a checkout
/// under `mktemp -d`), so a copy is made in a directory of its own (again
/// if a test that finished removed it).
fn netfi_for_nobody() -> String {
    use std::os::unix::fs::PermissionsExt;
    let dir = std::env::temp_dir().join(format!("netfi-host-exe-{}", std::process::id()));
    let exe = dir.join("netfi");
    if !exe.exists() {
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let tmp = dir.join("netfi.tmp");
        std::fs::copy(netfi_exe(), &tmp).unwrap();
        std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o755)).unwrap();
        std::fs::rename(&tmp, &exe).unwrap();
    }
    exe.to_str().unwrap().to_string()
}

/// Removes the copy [`netfi_for_nobody`] made, if any.
fn remove_netfi_for_nobody() {
    let _ = std::fs::remove_dir_all(std::env::temp_dir().join(format!("netfi-host-exe-{}", std::process::id())));
}

/// `netfi …` as the user nobody.
fn as_nobody(args: &[&str]) -> Command {
    as_user(NOBODY, args)
}

/// `netfi …` as user `uid` (group `uid`), without `$XDG_RUNTIME_DIR`.
fn as_user(uid: u32, args: &[&str]) -> Command {
    let mut c = Command::new("setpriv");
    c.args([&format!("--reuid={uid}"), &format!("--regid={uid}"), "--clear-groups", &netfi_for_nobody()])
        .args(args)
        .current_dir("/tmp")
        .env_remove("XDG_RUNTIME_DIR");
    c
}

fn have_setpriv() -> bool {
    Command::new("setpriv").arg("--version").output().is_ok_and(|o| o.status.success())
}

/// Whether a test that acts as other users must skip: it needs root and
/// `setpriv`, and fails without them where `NETFI_REQUIRE_ROOT` is set.
fn skip_unless_other_users() -> bool {
    if skip_unless_root("acting as another user") {
        return true;
    }
    assert!(have_setpriv() || std::env::var_os("NETFI_REQUIRE_ROOT").is_none(), "NETFI_REQUIRE_ROOT is set but `setpriv` (util-linux) is missing");
    if !have_setpriv() {
        eprintln!("skipped: acting as another user needs setpriv");
    }
    !have_setpriv()
}

#[test]
fn a_run_leaves_nothing_in_dev_shm_and_another_user_runs_after_root() {
    let _guard = machine::alone();
    let run_id = format!("hostshm{}", std::process::id());
    let out = out_dir("shm");
    let o = netfi().args(["run", "Normal", "--duration-s", "1", "--seed", "4", "--no-isolate", "--run-id", &run_id, "--out"]).arg(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let left = shm_with(&run_id);
    assert!(left.is_empty(), "the run left {left:?} in /dev/shm");
    // This user's iceoryx2 directory is private.
    let root = std::fs::metadata(netfi::transport::ipc::user_root_dir()).unwrap();
    assert_eq!(root.mode() & 0o077, 0, "mode {:o}", root.mode());
    assert_eq!(root.uid(), uid());
    let _ = std::fs::remove_dir_all(&out);

    if skip_unless_other_users() {
        return;
    }
    // Another user, after root.
    let out = out_dir("nobody");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::chown(&out, Some(NOBODY), Some(NOBODY)).unwrap();
    let nobody_run = format!("nobody{}", std::process::id());
    let o = as_nobody(&["run", "Normal", "--duration-s", "1", "--seed", "4", "--run-id", &nobody_run, "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    let left = shm_with(&nobody_run);
    // What the second user's run created is its own: clean up as root.
    let _ = std::fs::remove_dir_all(format!("/tmp/netfi-iceoryx2-{NOBODY}"));
    let _ = std::fs::remove_dir_all(format!("/tmp/netfi-{NOBODY}"));
    let _ = std::fs::remove_dir_all(&out);
    remove_netfi_for_nobody();
    assert!(o.status.success(), "a second user could not run after root:\n{stderr}");
    assert!(left.is_empty(), "the second user's run left {left:?} in /dev/shm");
}

#[test]
fn a_file_planted_by_another_user_is_refused_at_once() {
    if skip_unless_other_users() {
        return;
    }
    let _guard = machine::alone();
    let run_id = format!("planted{}", std::process::id());
    let planted = format!("/dev/shm/netfi_u{}_{run_id}_node.global_mgmt", uid());
    let o = Command::new("setpriv")
        .args([&format!("--reuid={NOBODY}"), &format!("--regid={NOBODY}"), "--clear-groups", "touch", &planted])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = out_dir("planted");
    let mut child = netfi()
        .args(["run", "Normal", "--duration-s", "1", "--no-isolate", "--run-id", &run_id, "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // A guard against a hang, not a timing assertion.
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let o = child.wait_with_output().unwrap();
    let _ = std::fs::remove_file(&planted);
    for role in ["console", "emulator", "simulator"] {
        if let Some(pid) = read_pid(&out, role).filter(|p| alive(*p)) {
            sigkill(pid);
        }
    }
    restore();
    let _ = std::fs::remove_dir_all(&out);
    let stderr = String::from_utf8_lossy(&o.stderr);
    let status = status.unwrap_or_else(|| panic!("the run hung on a planted file:\n{stderr}"));
    assert!(!status.success(), "a planted file was used");
    assert!(stderr.contains(&format!("belongs to uid {NOBODY}")), "{stderr}");
}

/// Directories another user made first under a user's usual names (the
/// records' and iceoryx2's) do not lock that user out: runs say whose they
/// are and use private ones of their own, found again by the next run.
#[test]
fn directories_taken_first_by_another_user_do_not_lock_a_user_out() {
    if skip_unless_other_users() {
        return;
    }
    let _guard = machine::alone();
    const USER: u32 = 54321;
    const SQUATTER: u32 = 12345;
    let taken = [format!("/tmp/netfi-iceoryx2-{USER}"), format!("/tmp/netfi-{USER}")];
    let clean = || {
        for e in std::fs::read_dir("/tmp").unwrap().filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with(&format!("netfi-iceoryx2-{USER}")) || name.starts_with(&format!("netfi-{USER}")) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    };
    clean();
    for d in &taken {
        std::fs::create_dir(d).unwrap();
        std::os::unix::fs::chown(d, Some(SQUATTER), Some(SQUATTER)).unwrap();
    }
    let out = out_dir("taken");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::chown(&out, Some(USER), Some(USER)).unwrap();
    let run = |n: u32| {
        let run_id = format!("taken{n}x{}", std::process::id());
        as_user(USER, &["run", "Normal", "--duration-s", "1", "--seed", "4", "--run-id", &run_id, "--out", out.to_str().unwrap()]).output().unwrap()
    };
    let (first, second) = (run(1), run(2));
    let restored = as_user(USER, &["restore"]).output().unwrap();
    let replacements: Vec<String> = std::fs::read_dir("/tmp")
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().display().to_string())
        .filter(|p| p.starts_with(&format!("/tmp/netfi-iceoryx2-{USER}-")) || p.starts_with(&format!("/tmp/netfi-{USER}-")))
        .collect();
    let private: Vec<bool> = replacements.iter().map(|p| std::fs::metadata(p).is_ok_and(|m| m.uid() == USER && m.mode() & 0o077 == 0)).collect();
    clean();
    let _ = std::fs::remove_dir_all(&out);
    remove_netfi_for_nobody();
    let text = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(first.status.success(), "a run was locked out by directories of uid {SQUATTER}:\n{}", text(&first));
    assert!(second.status.success(), "the second run failed:\n{}", text(&second));
    assert!(restored.status.success(), "`netfi restore` failed:\n{}", text(&restored));
    for o in [&first, &second, &restored] {
        assert!(text(o).contains(&format!("belongs to uid {SQUATTER}")), "whose the directory is was not said:\n{}", text(o));
    }
    // One replacement each for the records and iceoryx2, found again by
    // the second run and by `netfi restore`, closed to others.
    assert_eq!(replacements.len(), 2, "{replacements:?}");
    assert!(private.iter().all(|p| *p), "{replacements:?}");
}

/// What another user polling `/dev/shm` does while runs start: tries to
/// open read-write, as fast as it can, the run's management segment (its
/// name follows from the run id, which `ps` shows) and, every 64 tries,
/// every file of the run it lists. Prints whether it could open a 0666
/// decoy (the method works), its tries, the run's files it saw, and what
/// it opened.
const POLLER: &str = r#"
import os, sys
mgmt, needle, decoy, stop = sys.argv[1:5]
def opens(p):
    try:
        fd = os.open(p, os.O_RDWR | os.O_NOFOLLOW)
    except OSError:
        return False
    os.close(fd)
    return True
decoy_ok, tries, seen, opened = opens(decoy), 0, set(), set()
print("started", flush=True)
while not os.path.exists(stop):
    tries += 1
    if opens(mgmt):
        opened.add(mgmt)
    if tries % 64 == 0:
        for n in os.listdir("/dev/shm"):
            if needle in n:
                seen.add(n)
                if opens("/dev/shm/" + n):
                    opened.add(n)
print(decoy_ok, tries, len(seen), sorted(opened))
"#;

/// A run's shared memory is private from its first instant: another user
/// polling `/dev/shm` while runs start never opens one of its files
/// read-write (iceoryx2 makes the run's management segment 0666 for a
/// moment, unless netfi made it first).
#[test]
fn another_user_polling_dev_shm_never_opens_a_runs_segment_read_write() {
    use std::io::BufRead;
    if skip_unless_other_users() {
        return;
    }
    let _guard = machine::alone();
    let python = if Path::new("/usr/bin/python3").exists() { "/usr/bin/python3" } else { "python3" };
    let decoy = format!("/dev/shm/netfi-decoy-{}", std::process::id());
    std::fs::write(&decoy, b"").unwrap();
    std::fs::set_permissions(&decoy, std::os::unix::fs::PermissionsExt::from_mode(0o666)).unwrap();
    let mut results = Vec::new();
    for attempt in 0..3 {
        let run_id = format!("polled{attempt}x{}", std::process::id());
        let prefix = netfi::transport::IpcConfig::new(netfi::transport::RunId::new(&run_id).unwrap()).prefix().to_string();
        let mgmt = netfi::transport::ipc::mgmt_segment_path(&prefix);
        let stop = std::env::temp_dir().join(format!("netfi-poll-stop-{}-{attempt}", std::process::id()));
        let _ = std::fs::remove_file(&stop);
        let mut poller = Reaped(
            Command::new("setpriv")
                .args([&format!("--reuid={NOBODY}"), &format!("--regid={NOBODY}"), "--clear-groups", python, "-c", POLLER])
                .args([mgmt.to_str().unwrap(), &run_id, &decoy, stop.to_str().unwrap()])
                .current_dir("/tmp")
                .stdout(std::process::Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let mut lines = std::io::BufReader::new(poller.0.stdout.take().unwrap()).lines();
        assert_eq!(lines.next().and_then(Result::ok).as_deref(), Some("started"), "the poller did not start ({python})");
        let out = out_dir(&format!("polled{attempt}"));
        let o = netfi().args(["run", "Normal", "--duration-s", "1", "--seed", "4", "--no-isolate", "--run-id", &run_id, "--out"]).arg(&out).output().unwrap();
        std::fs::write(&stop, b"").unwrap();
        let said = lines.next().and_then(Result::ok).unwrap_or_default();
        let _ = poller.0.wait();
        let _ = std::fs::remove_file(&stop);
        let _ = std::fs::remove_dir_all(&out);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        results.push(said);
    }
    let _ = std::fs::remove_file(&decoy);
    remove_netfi_for_nobody();
    for said in &results {
        let mut words = said.splitn(4, ' ');
        let (decoy_ok, tries, seen, opened) = (words.next(), words.next(), words.next(), words.next().unwrap_or(""));
        assert_eq!(decoy_ok, Some("True"), "the poller could not open even a 0666 file: {results:?}");
        assert!(tries.and_then(|t| t.parse::<u64>().ok()).is_some_and(|t| t > 0), "{results:?}");
        assert!(seen.and_then(|n| n.parse::<u64>().ok()).is_some_and(|n| n > 0), "the poller never saw the run's files: {results:?}");
        assert_eq!(opened, "[]", "another user opened a run's shared memory read-write: {results:?}");
    }
}

/// Root's `netfi run` into a directory another user owns: refused unless
/// asked (`--out-owned-by-other`); asked, it follows none of the links
/// that user planted at every name a run writes and at each one's
/// `.partial`, and writes around them; a link at the lock's name is
/// refused.
#[test]
fn a_run_never_follows_links_another_user_planted_in_its_directory() {
    if skip_unless_other_users() {
        return;
    }
    let _guard = machine::alone();
    let pid = std::process::id();
    // Every name a run leaves in its directory, from a run of root's own,
    // and those it writes and removes on its way.
    let reference = out_dir("names");
    let o = netfi().args(["run", "Normal", "--duration-s", "1", "--seed", "4", "--no-isolate", "--run-id", &format!("names{pid}"), "--out"]).arg(&reference).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run_id = format!("planted{pid}x");
    let mut names: Vec<String> = std::fs::read_dir(&reference).unwrap().filter_map(|e| e.ok()?.file_name().into_string().ok()).collect();
    names.extend(["trace_emulator.csv", "run.unfinished", "report.json"].map(String::from));
    names.push(format!("scenario.{run_id}.toml"));
    names.retain(|n| n != "run.lock");
    names.sort();
    names.dedup();
    let _ = std::fs::remove_dir_all(&reference);
    assert!(names.len() >= 20, "{names:?}");
    let victims = out_dir("victim");
    std::fs::create_dir_all(&victims).unwrap();
    let victim = victims.join("secret");
    std::fs::write(&victim, b"root's own\n").unwrap();
    std::fs::set_permissions(&victim, std::os::unix::fs::PermissionsExt::from_mode(0o600)).unwrap();
    let out = out_dir("planted-links");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::chown(&out, Some(NOBODY), Some(NOBODY)).unwrap();
    let plant = |names: &[String]| {
        let o = Command::new("setpriv")
            .args([&format!("--reuid={NOBODY}"), &format!("--regid={NOBODY}"), "--clear-groups", "sh", "-c", r#"v="$1"; shift; for n in "$@"; do ln -s "$v" "$n" && ln -s "$v" "$n.partial" || exit 1; done"#, "plant"])
            .arg(&victim)
            .args(names)
            .current_dir(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    plant(&names);
    let run = |extra: &[&str]| {
        netfi().args(["run", "Normal", "--duration-s", "1", "--seed", "4", "--no-isolate", "--run-id", &run_id, "--out"]).arg(&out).args(extra).output().unwrap()
    };
    let refused = run(&[]);
    let asked = run(&["--out-owned-by-other"]);
    let links: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_symlink()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let kept = std::fs::read(&victim).unwrap();
    // The lock the run left, replaced by a link.
    std::fs::remove_file(out.join("run.lock")).unwrap();
    plant(&["run.lock".to_string()]);
    let locked = run(&["--out-owned-by-other"]);
    let kept_after_lock = std::fs::read(&victim).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&victims);
    remove_netfi_for_nobody();
    let text = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!refused.status.success(), "a directory of uid {NOBODY} was written into unasked");
    assert!(text(&refused).contains(&format!("belongs to uid {NOBODY}")) && text(&refused).contains("--out-owned-by-other"), "{}", text(&refused));
    assert!(asked.status.success(), "{}", text(&asked));
    assert_eq!(kept, b"root's own\n", "a planted link was written through");
    assert!(links.is_empty(), "links left where the run wrote (each should have been removed, not followed): {links:?} of {names:?}");
    assert!(!locked.status.success() && text(&locked).contains("run.lock is a symbolic link"), "{}", text(&locked));
    assert_eq!(kept_after_lock, b"root's own\n");
}
