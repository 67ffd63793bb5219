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
//!
//! # What is bounded, what is only said
//!
//! A small file may hold a great many records (LZ4 packs a repeated record
//! into a few bytes: 22 MB held 40 million), so [`load`] and [`parse`] read
//! at most [`CaptureLimits::max_records`] ([`DEFAULT_MAX_RECORDS`] unless
//! raised: [`load_with`]), and so at most that many records' bytes of
//! content, refused ([`CaptureError::TooManyRecords`]) when the next record
//! begins, before it is kept; what is kept never outgrows the limit.
//!
//! A file without an LZ4 content checksum is read, but nothing shows it is
//! as written: each frame's ITP checksum is checked, but no checksum covers
//! the records' time stamps and flags or delays, nor the frame fields the
//! ITP checksum leaves out ([`unverified_fields`], [`CaptureNote::unverified`]);
//! a flipped byte there passes unless the time rule catches it. The
//! programs that load a capture say so on stderr and in their reports.


mod error;
mod reader;
mod record;
mod stats;
mod writer;

pub use error::CaptureError;
pub use reader::{CaptureReader, LZ4_MAGIC};
pub use record::{CaptureRecord, RecordLayout, DELAY_RECORD_HEADER_LEN, RECORD_HEADER_LEN, RECORD_LEN};
pub use stats::{unverified_fields, CaptureNote, CaptureStats, FRAME_FIELDS_UNCHECKED};
pub use writer::CaptureWriter;

use std::io::Read;
use std::path::{Path, PathBuf};


/// Longest step backwards in time between consecutive records that [`load`]
/// accepts (and counts): 1 s.
pub const MAX_STEP_BACKWARD_NS: u64 = 1_000_000_000;

/// Longest gap forwards in time between consecutive records that [`load`]
/// accepts: 60 s.
pub const MAX_GAP_NS: u64 = 60_000_000_000;

/// The records a capture is read up to unless a higher limit is given:
/// 4,194,304 (2^22), 70 minutes at 1 kHz, 2 h 15 min at the shipped
/// recording's 517 Hz; at most 579 MB of content, 604 MB in memory.
pub const DEFAULT_MAX_RECORDS: u64 = 1 << 22;

/// How much of a capture is read: at most `max_records` records, so at
/// most [`CaptureLimits::max_content_bytes`] of decompressed content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureLimits {
    /// The most records read; one more is [`CaptureError::TooManyRecords`].
    pub max_records: u64,
}

impl Default for CaptureLimits {
    fn default() -> Self {
        CaptureLimits { max_records: DEFAULT_MAX_RECORDS }
    }
}

impl CaptureLimits {
    /// At most `max_records` records.
    pub const fn records(max_records: u64) -> CaptureLimits {
        CaptureLimits { max_records }
    }

    /// The most content decompressed for the records: a record of the
    /// larger layout each, and the header of the one refused.
    pub const fn max_content_bytes(self) -> u64 {
        self.max_records.saturating_mul((DELAY_RECORD_HEADER_LEN + crate::frame::FRAME_LEN) as u64).saturating_add(DELAY_RECORD_HEADER_LEN as u64)
    }
}

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

impl Capture {
    /// What the capture is, for reports and stderr ([`CaptureNote`]).
    pub fn note(&self) -> CaptureNote {
        CaptureNote::new(&self.path, self.layout, &self.stats)
    }
}

/// What reading a capture through [`scan`] found: its layout and counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scanned {
    /// The record layout found.
    pub layout: RecordLayout,
    /// The counts over every record.
    pub stats: CaptureStats,
}

/// Reads a whole capture file, of at most [`DEFAULT_MAX_RECORDS`], and
/// checks it by the rule in the module docs: any malformed record or LZ4
/// frame, bytes after a frame that begin no other, a file without
/// records, or damage ([`CaptureStats::refusal`]) is an error. Only a
/// regular file is read ([`crate::load::open_regular`]).
pub fn load(path: impl AsRef<Path>) -> Result<Capture, CaptureError> {
    load_with(path, CaptureLimits::default())
}

/// [`load`], read up to `limits`.
pub fn load_with(path: impl AsRef<Path>, limits: CaptureLimits) -> Result<Capture, CaptureError> {
    let path = path.as_ref();
    keep_all(CaptureReader::open(path)?, Some(path), limits)
}

/// [`load`] for a capture already in memory.
pub fn parse(bytes: &[u8]) -> Result<Capture, CaptureError> {
    parse_with(bytes, CaptureLimits::default())
}

/// [`parse`], read up to `limits`.
pub fn parse_with(bytes: &[u8], limits: CaptureLimits) -> Result<Capture, CaptureError> {
    keep_all(CaptureReader::new(bytes), None, limits)
}

/// Reads a capture up to `limits` and checks it as [`load`] does, handing
/// each record to `each` instead of keeping it: for a caller that needs
/// a part of each record only (a replay stage, the delays).
pub fn scan<R: Read>(reader: CaptureReader<R>, limits: CaptureLimits, each: impl FnMut(&CaptureRecord)) -> Result<Scanned, CaptureError> {
    let path = reader.path().map(Path::to_path_buf);
    read_checked(reader, path.as_deref(), limits, each)
}

/// [`read_checked`], keeping every record; what is kept grows by doubling
/// but never beyond the limit.
fn keep_all<R: Read>(reader: CaptureReader<R>, path: Option<&Path>, limits: CaptureLimits) -> Result<Capture, CaptureError> {
    let mut records = Vec::new();
    let room = usize::try_from(limits.max_records).unwrap_or(usize::MAX);
    let Scanned { layout, stats } = read_checked(reader, path, limits, |r| {
        if records.len() == records.capacity() {
            records.reserve_exact(records.len().max(1024).min(room.saturating_sub(records.len()).max(1)));
        }
        records.push(*r);
    })?;
    Ok(Capture { path: path.map(Path::to_path_buf).unwrap_or_default(), records, layout, stats })
}

fn read_checked<R: Read>(reader: CaptureReader<R>, path: Option<&Path>, limits: CaptureLimits, mut each: impl FnMut(&CaptureRecord)) -> Result<Scanned, CaptureError> {
    let mut reader = reader.with_max_records(limits.max_records);
    let mut stats = CaptureStats::default();
    for record in reader.by_ref() {
        let record = record?;
        stats.push(&record);
        each(&record);
    }
    if stats.frames == 0 {
        return Err(CaptureError::Empty { path: path.map(Path::to_path_buf) });
    }
    stats.content_checksum = reader.has_content_checksum();
    stats.lz4_frames = reader.lz4_frames();
    if let Some(why) = stats.refusal() {
        return Err(CaptureError::Damaged { path: path.map(Path::to_path_buf), why, stats: Box::new(stats) });
    }
    let layout = reader.layout().unwrap_or(RecordLayout::Dropped);
    Ok(Scanned { layout, stats })
}

#[cfg(test)]
mod tests;
