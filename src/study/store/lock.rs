//! The claims on a study's files: a participant's lock, held while their
//! state is advanced, and a short lock on the study's shared files.

use super::state::{load_state, save_state, AttemptState, ParticipantState};
use super::{io, now_utc, OpenStudy, StudyError};
use std::path::Path;


/// The exclusive claim on a participant: an `flock` on `DATA/P/lock`,
/// held as long as this value lives (the kernel lets it go when the
/// process ends, however it ends). The file holds the holder's pid and
/// what it does, so a refused command can say who holds it.
#[derive(Debug)]
pub struct ParticipantLock {
    file: std::fs::File,
}

impl ParticipantLock {
    /// Takes the lock of the participant folder `dir` (created if need
    /// be) without waiting, saying what the holder does (`what`).
    pub fn take(dir: &Path, id: &str, what: &str) -> Result<ParticipantLock, StudyError> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join("lock");
        let mut file =
            std::fs::OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path).map_err(io(&path))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let holder = if text.trim().is_empty() { "another process".to_string() } else { text.trim().to_string() };
                return Err(StudyError::Busy { id: id.to_string(), holder, lock: path });
            }
            return Err(io(&path)(err));
        }
        let line = format!("pid {} ({what}, since {})\n", std::process::id(), now_utc());
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| file.write_all(line.as_bytes())).map_err(io(&path))?;
        Ok(ParticipantLock { file })
    }

    /// Lets the lock go and empties its file.
    pub fn release(self) {
        let _ = self.file.set_len(0);
    }
}

/// A short exclusive claim on a whole study's shared files, waited for.
pub(super) struct StudyLock {
    _file: std::fs::File,
}

impl StudyLock {
    pub(super) fn take(path: &Path) -> Result<StudyLock, StudyError> {
        use std::os::fd::AsRawFd;
        let file = std::fs::OpenOptions::new().write(true).create(true).truncate(false).open(path).map_err(io(path))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(io(path)(std::io::Error::last_os_error()));
        }
        Ok(StudyLock { _file: file })
    }
}

/// Whether process `pid` is alive and its command line names `needle`.
pub fn process_names(pid: u32, needle: &str) -> bool {
    std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| String::from_utf8_lossy(&c).contains(needle))
}

/// Takes participant `p`'s lock and brings their state up to date: an
/// attempt still `running` had its runner die, and is `interrupted` (its
/// `netfi run`, if still stopping, is waited for: the trial's next attempt
/// must not share the emulator's core with it).
pub fn claim(s: &OpenStudy, p: usize, what: &str) -> Result<(ParticipantLock, ParticipantState), StudyError> {
    let dir = s.participant_dir(p);
    let id = &s.study.participants[p].id;
    let lock = ParticipantLock::take(&dir, id, what)?;
    let mut state = load_state(&dir)?.unwrap_or_else(|| ParticipantState { participant: id.clone(), attempts: Vec::new() });
    let mut changed = false;
    for a in state.attempts.iter_mut().filter(|a| a.state == AttemptState::Running) {
        if let Some(pid) = a.run_pid {
            let out = dir.join(&a.dir);
            let needle = out.display().to_string();
            let t0 = std::time::Instant::now();
            while process_names(pid, &needle) && t0.elapsed() < std::time::Duration::from_secs(60) {
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        }
        a.state = AttemptState::Interrupted;
        a.report = dir.join(&a.dir).join("report.json").is_file();
        a.ended_utc = Some(now_utc());
        a.runner_pid = None;
        if a.note.is_empty() {
            a.note = "its runner ended while the trial was running".into();
        }
        changed = true;
    }
    if changed {
        save_state(&dir, &state)?;
    }
    Ok((lock, state))
}
