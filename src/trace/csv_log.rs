//! A CSV written row by row by the thread that has the rows.

use super::FLUSH_EVERY;
use crate::durable::{DurableError, PartialFile};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A CSV written as its rows come, by the thread that has them (the
/// simulator's `received.csv`, the console's `video_received.csv`):
/// buffered, flushed at least once a second when rows keep coming
/// ([`CsvLog::tick`]), so that memory stays flat however long the run and
/// a killed process leaves its rows up to its last second. Nothing is
/// allocated per row. The file is `NAME.partial` until [`CsvLog::finish`]
/// has written it whole (a killed process leaves it so). The first failed
/// write is kept, later rows are skipped, and [`CsvLog::finish`] reports it
/// naming the file, which keeps its `.partial` name: a full disk is an
/// error and a file marked cut.
pub struct CsvLog {
    path: PathBuf,
    w: std::io::BufWriter<PartialFile>,
    error: Option<std::io::Error>,
    rows: u64,
    last_flush_ns: u64,
}

impl CsvLog {
    /// Creates `path.partial` with its `header` line; an error names the
    /// file.
    pub fn create(path: PathBuf, header: &str) -> Result<CsvLog, DurableError> {
        let file = PartialFile::create(&path)?;
        let partial = file.partial().to_path_buf();
        let mut w = std::io::BufWriter::with_capacity(1 << 16, file);
        writeln!(w, "{header}").map_err(|source| DurableError::Write { path: partial, source })?;
        Ok(CsvLog { path, w, error: None, rows: 0, last_flush_ns: 0 })
    }

    /// Appends one row, which `write` writes (its line's end included).
    #[inline]
    pub fn push(&mut self, write: impl FnOnce(&mut std::io::BufWriter<PartialFile>) -> std::io::Result<()>) {
        if self.error.is_none() {
            match write(&mut self.w) {
                Ok(()) => self.rows += 1,
                Err(e) => self.error = Some(e),
            }
        }
    }

    /// Flushes what is buffered if the last flush was a second or more
    /// before `now_ns` (any clock, as long as the caller keeps to one).
    #[inline]
    pub fn tick(&mut self, now_ns: u64) {
        if now_ns.saturating_sub(self.last_flush_ns) >= FLUSH_EVERY.as_nanos() as u64 {
            self.last_flush_ns = now_ns;
            if self.error.is_none() {
                if let Err(e) = self.w.flush() {
                    self.error = Some(e);
                }
            }
        }
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// The file, as it is named once whole.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes what is buffered and gives the file its own name; returns
    /// it. The first failed write is the error, naming the file, which
    /// then stays `NAME.partial`.
    pub fn finish(mut self) -> Result<PathBuf, DurableError> {
        let partial = self.w.get_ref().partial().to_path_buf();
        if let Some(source) = self.error.take() {
            return Err(DurableError::Write { path: partial, source });
        }
        let file = self.w.into_inner().map_err(|e| DurableError::Write { path: partial, source: e.into_error() })?;
        file.commit()
    }
}
