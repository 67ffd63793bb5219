//! Recorded ITP captures (docs/spec.md §7): reading, writing and summarising them.
//!
//! A capture is a sequence of one or more complete standard LZ4 frames
//! (what `lz4 -d` decodes as one stream); their decompressed content, read
//! as one stream across the frames, is a sequence of records:
//!
//! ```text
//! u64 BE time_ns | u16 BE length | u8 dropped | payload (length bytes)
//! ```
//!
//! `time_ns` is the recorder's receive time (the shipped capture uses the wall
//! clock), `dropped` a flag byte kept as written, and the payload one ITP frame
//! of 124 bytes.
//!
//! The study's delay-trial captures use a second record layout, where the
//! delay in seconds the study's tool drew for the frame follows the length
//! field in place of the flag byte ([`RecordLayout::Delay`]):
//!
//! ```text
//! u64 BE time_ns | u16 BE length | f32 BE delay_s | payload (length bytes)
//! ```
//!
//! The reader tells the two apart on the first records (where the second
//! record's length field falls, and, for a capture of one record, its
//! size; when both layouts fit, whichever makes the first frame's ITP
//! checksum match) and says which it found ([`CaptureReader::layout`],
//! [`Capture::layout`]). A delay capture's records carry their delay in
//! [`CaptureRecord::delay_s`]; its `dropped` is 0. A record of any other length is an error that names the record
//! index and its byte offset in the decompressed stream; so is a stream that
//! ends inside a record.
//!
//! [`CaptureReader`] streams records from any [`Read`] without allocating per
//! record; [`CaptureWriter`] writes the same format, every LZ4 frame with
//! its content checksum (xxHash32 of everything it decompresses to), so
//! damage to a file written here is always found, and may close a frame
//! and start the next as it goes ([`CaptureWriter::end_frame`], a recorder
//! that flushes every batch); [`load`] reads a whole file and derives
//! [`CaptureStats`]. This is I/O code: the sans-IO core never calls it, only
//! the services and tools do.
//!
//! # What is refused, what is only counted
//!
//! A capture is replayed as the traffic of a real console, so a damaged one
//! must not pass for one. [`load`] (and [`parse`]) refuse, with an error that
//! says what was found:
//!
//! - anything that is not a sequence of complete, well-formed LZ4 frames of
//!   whole records: not LZ4, a corrupt block, a content checksum that does
//!   not match, a frame without its end mark (cut short, the last or any
//!   other), a record cut short or of a length other than one ITP frame, no
//!   records;
//! - bytes after a frame that do not begin another
//!   ([`CaptureError::TrailingBytes`]): garbage appended or between frames.
//!   LZ4's skippable frames (magic `0x184D2A50`–`5F`, metadata) are
//!   skipped, as `lz4 -d` skips them, when they are whole; the legacy LZ4
//!   format, which has no end mark, is refused as cut short;
//! - a time step backwards of more than [`MAX_STEP_BACKWARD_NS`] (1 s) or a
//!   gap forwards of more than [`MAX_GAP_NS`] (60 s) between two records: a
//!   wall clock steps back by milliseconds, not seconds, and a recording
//!   paused for more than a minute is two recordings; either is far more
//!   likely a flipped bit in a time stamp or two files joined;
//! - a frame whose ITP checksum is wrong, *unless* the file carries an LZ4
//!   content checksum: without one the file's integrity is unknown and a
//!   wrong frame checksum is read as damage to the file; with one (in every
//!   LZ4 frame of the file) the file is known to be as written, so the
//!   frame was recorded that way (a corrupted datagram) and is only counted.
//!
//! Only counted, in [`CaptureStats`] (callers may print them): frames with a
//! wrong checksum in a checksummed file, steps backwards up to 1 s, the
//! longest gap, frames flagged dropped.


mod error;
mod reader;
mod record;
mod stats;
mod writer;

pub use error::CaptureError;
pub use reader::CaptureReader;
pub use record::{CaptureRecord, RecordLayout, DELAY_RECORD_HEADER_LEN, RECORD_HEADER_LEN, RECORD_LEN};
pub use stats::CaptureStats;
pub use writer::CaptureWriter;

use std::io::Read;
use std::path::{Path, PathBuf};


/// Longest step backwards in time between consecutive records that [`load`]
/// accepts (and counts): 1 s.
pub const MAX_STEP_BACKWARD_NS: u64 = 1_000_000_000;

/// Longest gap forwards in time between consecutive records that [`load`]
/// accepts: 60 s.
pub const MAX_GAP_NS: u64 = 60_000_000_000;

/// A whole capture in memory.
#[derive(Debug, Clone)]
pub struct Capture {
    /// The file it was read from.
    pub path: PathBuf,
    /// Every record, in file order.
    pub records: Vec<CaptureRecord>,
    /// The record layout found.
    pub layout: RecordLayout,
    /// Derived statistics.
    pub stats: CaptureStats,
}

/// Reads a whole capture file and checks it by the rule in the module docs:
/// any malformed record or LZ4 frame, bytes after a frame that begin no
/// other, a file without records,
/// or damage ([`CaptureStats::refusal`]) is an error.
pub fn load(path: impl AsRef<Path>) -> Result<Capture, CaptureError> {
    let path = path.as_ref();
    read_checked(CaptureReader::open(path)?, Some(path))
}

/// [`load`] for a capture already in memory.
pub fn parse(bytes: &[u8]) -> Result<Capture, CaptureError> {
    read_checked(CaptureReader::new(bytes), None)
}

fn read_checked<R: Read>(mut reader: CaptureReader<R>, path: Option<&Path>) -> Result<Capture, CaptureError> {
    let mut records = Vec::new();
    let mut stats = CaptureStats::default();
    for record in reader.by_ref() {
        let record = record?;
        stats.push(&record);
        records.push(record);
    }
    if records.is_empty() {
        return Err(CaptureError::Empty { path: path.map(Path::to_path_buf) });
    }
    stats.content_checksum = reader.has_content_checksum();
    stats.lz4_frames = reader.lz4_frames();
    if let Some(why) = stats.refusal() {
        return Err(CaptureError::Damaged { path: path.map(Path::to_path_buf), why, stats: Box::new(stats) });
    }
    let layout = reader.layout().unwrap_or(RecordLayout::Dropped);
    Ok(Capture { path: path.map(Path::to_path_buf).unwrap_or_default(), records, layout, stats })
}

#[cfg(test)]
mod tests;
