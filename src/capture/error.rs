//! What can go wrong reading or writing a capture.

use super::CaptureStats;
use std::fmt;
use std::io;
use std::path::PathBuf;

/// Where a capture came from, for error messages.
struct Origin<'a>(&'a Option<PathBuf>);

impl fmt::Display for Origin<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(path) => write!(f, "capture `{}`", path.display()),
            None => f.write_str("capture stream"),
        }
    }
}

/// Everything that can go wrong reading or writing a capture. Every variant
/// names the file (`path`, `None` for an anonymous stream) and, where there is
/// one, the record (0-based index) and its byte offset in the decompressed
/// stream.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The file could not be opened or created.
    #[error("{}: cannot open: {source}", Origin(.path))]
    Open {
        path: Option<PathBuf>,
        #[source]
        source: io::Error,
    },
    /// The bytes are not a valid LZ4 frame (wrong magic number, corrupt block,
    /// bad checksum): the file is not a capture, or it is damaged.
    #[error("{}: record {record} at byte {offset}: not a valid LZ4 frame ({source}); \
             a capture is a sequence of standard LZ4 frames", Origin(.path))]
    Lz4 {
        path: Option<PathBuf>,
        record: u64,
        offset: u64,
        #[source]
        source: lz4_flex::frame::Error,
    },
    /// Reading the underlying file failed.
    #[error("{}: record {record} at byte {offset}: read failed: {source}", Origin(.path))]
    Read {
        path: Option<PathBuf>,
        record: u64,
        offset: u64,
        #[source]
        source: io::Error,
    },
    /// A record's length field is not 124, the size of an ITP frame.
    #[error("{}: record {record} at byte {offset}: payload length {length}, expected {expected} \
             (one ITP frame)", Origin(.path))]
    WrongLength {
        path: Option<PathBuf>,
        record: u64,
        offset: u64,
        /// The length field as written.
        length: u16,
        /// Always [`FRAME_LEN`].
        expected: usize,
    },
    /// The content ends inside a record: the capture was cut short.
    #[error("{}: record {record} at byte {offset}: truncated, {found} of {needed} bytes present",
            Origin(.path))]
    Truncated {
        path: Option<PathBuf>,
        record: u64,
        offset: u64,
        /// Bytes the record needs (header, or header and payload).
        needed: usize,
        /// Bytes present before the content ended.
        found: usize,
    },
    /// The file ends inside an LZ4 frame's header, block or checksum: it
    /// was cut short there. `file_bytes` is where, in the file (its
    /// length); `record` the records read whole before it.
    #[error("{}: the file was cut short: it ends at byte {file_bytes} of the file, inside LZ4 frame {frame} (from 1); \
             the {record} record(s) before it were whole", Origin(.path))]
    Cut {
        path: Option<PathBuf>,
        record: u64,
        /// The frame cut, counted from 1.
        frame: u64,
        /// Where the file ends, in compressed bytes.
        file_bytes: u64,
    },
    /// More records than the limit the capture is read with: refused when
    /// the first byte of the record beyond it is read.
    #[error("{}: more than {max_records} records, the most it is read with (default {default}): \
             --capture-max-records, or a replay stage's `max_records`, raises the limit",
            Origin(.path), default = super::DEFAULT_MAX_RECORDS)]
    TooManyRecords {
        path: Option<PathBuf>,
        /// The limit read with.
        max_records: u64,
    },
    /// The file holds no records at all.
    #[error("{}: contains no records", Origin(.path))]
    Empty { path: Option<PathBuf> },
    /// An LZ4 frame ends without its end mark (and content checksum), or
    /// a skippable frame without its announced bytes: the file was cut
    /// short (or is in the legacy LZ4 format, which has no end mark).
    #[error("{}: LZ4 frame {frame} (from 1) ends after record {record} without its end mark: \
             the file was cut short", Origin(.path))]
    Unterminated {
        path: Option<PathBuf>,
        record: u64,
        /// The frame cut short, counted from 1.
        frame: u64,
    },
    /// Bytes after a complete LZ4 frame that do not begin another: garbage
    /// appended, or between frames.
    #[error("{}: {bytes} byte(s) after the end of LZ4 frame {frame} (after record {record}) \
             that are not an LZ4 frame; a capture is a sequence of complete LZ4 frames", Origin(.path))]
    TrailingBytes {
        path: Option<PathBuf>,
        /// Records read before the garbage.
        record: u64,
        /// Bytes from the garbage to the end of the file.
        bytes: u64,
        /// The complete frames before it (counted from 1: the last one's
        /// number).
        frame: u64,
    },
    /// The records are well formed but what they hold shows damage, by the
    /// rule in the module docs; `stats` has every count.
    #[error("{}: refused: {why}", Origin(.path))]
    Damaged {
        path: Option<PathBuf>,
        /// What was found, in words.
        why: String,
        /// The counts over the whole capture.
        stats: Box<CaptureStats>,
    },
    /// A payload handed to the writer is longer than the `u16` length field
    /// can describe.
    #[error("{}: record {record}: payload of {length} bytes does not fit the u16 length field",
            Origin(.path))]
    PayloadTooLong { path: Option<PathBuf>, record: u64, length: usize },
    /// Writing (or finishing the LZ4 frame) failed.
    #[error("{}: record {record}: write failed: {source}", Origin(.path))]
    Write {
        path: Option<PathBuf>,
        record: u64,
        #[source]
        source: io::Error,
    },
}
