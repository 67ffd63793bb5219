//! Where a run comes from: this process's version, command line and host,
//! and when the run began.

use super::Provenance;

impl Provenance {
    /// This process's version, command line and host name; `started` is the
    /// wall-clock time the run began.
    pub fn capture(started: std::time::SystemTime, seed: u64) -> Provenance {
        let words: Vec<String> = std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect();
        // Only a word with a NUL byte cannot be quoted; an argument never has one.
        let command_line = shlex::try_join(words.iter().map(String::as_str)).unwrap_or_else(|_| words.join(" "));
        Provenance {
            version: env!("CARGO_PKG_VERSION").to_string(),
            command_line,
            started_utc: humantime::format_rfc3339_seconds(started).to_string(),
            seed,
            host: host_name(),
        }
    }
}

/// The host's name (`gethostname`), or `unknown`.
fn host_name() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is writable for its whole length; the name is
    // NUL-terminated within it unless truncated, which the search below allows for.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let len = buf.iter().position(|b| *b == 0).unwrap_or(buf.len());
    if rc != 0 || len == 0 {
        return "unknown".into();
    }
    String::from_utf8_lossy(&buf[..len]).into_owned()
}
