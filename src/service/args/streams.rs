//! Where the streams of a run live: the run id of each stream's services
//! and its directory. The same names for `netfi run`, which starts each
//! stream's ends, and the emulator, which serves them all.

use std::path::{Path, PathBuf};

/// The run id whose services stream `k` uses: the run's own for stream 0,
/// `<run>-s<k>` for the others (`netfi/<run>-s<k>/console`, ...).
pub fn run_id(run_id: &str, k: usize) -> String {
    if k == 0 {
        run_id.to_string()
    } else {
        format!("{run_id}-s{k}")
    }
}

/// Where stream `k` of a run of `streams` writes: the run's directory for
/// a single stream, `<out>/stream-<k>/` otherwise.
pub fn dir(out: &Path, streams: usize, k: usize) -> PathBuf {
    if streams <= 1 {
        out.to_path_buf()
    } else {
        out.join(format!("stream-{k}"))
    }
}
