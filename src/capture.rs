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

use crate::frame::{FrameError, ItpFrame, ItpView, FRAME_LEN, SURGEON_ENGAGED};
use lz4_flex::frame::{FrameDecoder, FrameEncoder};
use std::fmt;
use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Bytes in a record header: time (8), length (2), dropped flag (1).
pub const RECORD_HEADER_LEN: usize = 11;

/// Bytes in a record that carries one ITP frame.
pub const RECORD_LEN: usize = RECORD_HEADER_LEN + FRAME_LEN;

/// Bytes in a delay capture's record header: time (8), length (2), delay (4).
pub const DELAY_RECORD_HEADER_LEN: usize = 14;

/// The two record layouts a capture may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordLayout {
    /// `u64 time_ns | u16 len | u8 dropped | payload`: netfi's and the
    /// study's console recordings.
    Dropped,
    /// `u64 time_ns | u16 len | f32 delay_s | payload`: the study's
    /// delay-trial captures.
    Delay,
}

impl RecordLayout {
    /// Bytes before the payload.
    pub const fn header_len(self) -> usize {
        match self {
            RecordLayout::Dropped => RECORD_HEADER_LEN,
            RecordLayout::Delay => DELAY_RECORD_HEADER_LEN,
        }
    }

    /// The layout in words, for reports.
    pub const fn describe(self) -> &'static str {
        match self {
            RecordLayout::Dropped => "time | length | dropped flag | frame",
            RecordLayout::Delay => "time | length | delay (s) | frame",
        }
    }
}

/// Longest step backwards in time between consecutive records that [`load`]
/// accepts (and counts): 1 s.
pub const MAX_STEP_BACKWARD_NS: u64 = 1_000_000_000;

/// Longest gap forwards in time between consecutive records that [`load`]
/// accepts: 60 s.
pub const MAX_GAP_NS: u64 = 60_000_000_000;

/// The LZ4 frame format's magic number, little-endian on the wire.
const LZ4_MAGIC: [u8; 4] = [0x04, 0x22, 0x4d, 0x18];
/// The magic numbers of LZ4's skippable frames, `0x184D2A50`–`0x184D2A5F`,
/// without their low four bits.
const LZ4_SKIPPABLE_MAGIC: u32 = 0x184D_2A50;
/// Bit of the frame descriptor's FLG byte (the fifth byte of a frame) that
/// announces a content checksum.
const LZ4_FLG_CONTENT_CHECKSUM: u8 = 0x04;

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
    /// Reading the underlying file failed (including a compressed stream that
    /// ends in the middle of an LZ4 block).
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

/// One record of a capture carrying an ITP frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureRecord {
    /// Receive time at the recorder, ns.
    pub time_ns: u64,
    /// The "dropped" flag byte as written (0: the frame was delivered; 0 in
    /// a delay capture).
    pub dropped: u8,
    /// The delay the study's tool drew for the frame, s (delay captures
    /// only).
    pub delay_s: Option<f32>,
    /// The ITP frame's wire bytes.
    pub payload: [u8; FRAME_LEN],
}

impl CaptureRecord {
    /// A record of a delivered frame.
    pub fn new(time_ns: u64, frame: &ItpFrame) -> CaptureRecord {
        CaptureRecord { time_ns, dropped: 0, delay_s: None, payload: frame.to_bytes() }
    }

    /// Whether the recorder flagged the frame as dropped.
    pub fn is_dropped(&self) -> bool {
        self.dropped != 0
    }

    /// A view of the payload (always one frame long).
    pub fn view(&self) -> ItpView<&[u8; FRAME_LEN]> {
        ItpView::new_unchecked(&self.payload)
    }

    /// The payload parsed, checksum verified.
    pub fn frame(&self) -> Result<ItpFrame, FrameError> {
        ItpFrame::parse(&self.view())
    }

    /// The payload parsed without judging the checksum.
    pub fn frame_unverified(&self) -> ItpFrame {
        ItpFrame::parse_unverified(&self.view())
    }
}

/// Fills `buf` from `reader` until it is full or the content ends; returns the
/// number of bytes read. Unlike `read_exact` it reports how much was there.
fn read_full<R: Read>(reader: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// The compressed stream under the decoder: counts what the decoder has
/// taken, hands back bytes the reader looked at ahead (the magic number of
/// the next frame), and notes each frame's FLG byte as it goes by.
struct Tap<R> {
    inner: R,
    /// Compressed bytes handed to the decoder so far.
    consumed: u64,
    /// Bytes read ahead of the decoder, handed to it first.
    back: [u8; 4],
    back_len: u8,
    back_pos: u8,
    /// Where the current frame's FLG byte is (its fifth byte), until it has
    /// gone by.
    flg_at: Option<u64>,
    /// LZ4 frames begun, and whether every one so far announces a content
    /// checksum.
    frames: u64,
    all_checksummed: bool,
    /// The decoder met the end of the stream. It treats that as the end of
    /// a frame even without the frame's end mark (a file cut at a block
    /// boundary), so the reader checks it.
    eof: bool,
}

impl<R: Read> Tap<R> {
    fn new(inner: R) -> Tap<R> {
        Tap { inner, consumed: 0, back: [0; 4], back_len: 0, back_pos: 0, flg_at: None, frames: 0, all_checksummed: true, eof: false }
    }

    /// Hands `bytes` (read ahead from `inner`) to the decoder before
    /// anything else; a frame starts with them when `frame`.
    fn push_back(&mut self, bytes: &[u8], frame: bool) {
        self.back[..bytes.len()].copy_from_slice(bytes);
        self.back_len = bytes.len() as u8;
        self.back_pos = 0;
        if frame {
            self.frames += 1;
            self.flg_at = Some(self.consumed + 4);
        }
    }
}

impl<R: Read> Read for Tap<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = if self.back_pos < self.back_len {
            let n = usize::from(self.back_len - self.back_pos).min(buf.len());
            let from = usize::from(self.back_pos);
            buf[..n].copy_from_slice(&self.back[from..from + n]);
            self.back_pos += n as u8;
            n
        } else {
            let n = self.inner.read(buf)?;
            self.eof |= n == 0 && !buf.is_empty();
            n
        };
        if let Some(at) = self.flg_at.filter(|&at| at >= self.consumed && at < self.consumed + n as u64) {
            self.all_checksummed &= buf[(at - self.consumed) as usize] & LZ4_FLG_CONTENT_CHECKSUM != 0;
            self.flg_at = None;
        }
        self.consumed += n as u64;
        Ok(n)
    }
}

/// Streams the records of a capture. Yields `Err` once and then ends if the
/// content is malformed, except for a record of the wrong length, which is
/// skipped (its length field says how far) so reading can go on. Bytes
/// after a frame that begin no other are an error
/// ([`CaptureError::TrailingBytes`]) after the last record before them.
pub struct CaptureReader<R: Read> {
    decoder: FrameDecoder<Tap<R>>,
    path: Option<PathBuf>,
    record: u64,
    offset: u64,
    done: bool,
    /// The record layout, once the first record has been looked at.
    layout: Option<RecordLayout>,
    /// Content read ahead to tell the layout, handed out before the
    /// decoder's: the bytes and how many have been handed out.
    ahead: Vec<u8>,
    ahead_pos: usize,
    /// Whether the first frame has been looked for.
    started: bool,
    /// The last frame has ended and nothing follows: the decoder is not
    /// asked again.
    content_ended: bool,
    /// What ended the content early (bytes that begin no frame, a frame cut
    /// short), found when the content read ahead reached it: given once
    /// the records before it have been read.
    boundary_error: Option<CaptureError>,
}

impl CaptureReader<BufReader<File>> {
    /// Opens a capture file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, CaptureError> {
        let path = path.as_ref();
        let file = File::open(path)
            .map_err(|source| CaptureError::Open { path: Some(path.to_path_buf()), source })?;
        Ok(CaptureReader::new(BufReader::new(file)).with_path(path))
    }
}

impl<R: Read> CaptureReader<R> {
    /// Reads a capture from an LZ4-compressed stream.
    pub fn new(reader: R) -> Self {
        CaptureReader {
            decoder: FrameDecoder::new(Tap::new(reader)),
            path: None,
            record: 0,
            offset: 0,
            done: false,
            layout: None,
            ahead: Vec::new(),
            ahead_pos: 0,
            started: false,
            content_ended: false,
            boundary_error: None,
        }
    }

    /// Names the stream's file in error messages.
    pub fn with_path(mut self, path: impl AsRef<Path>) -> Self {
        self.path = Some(path.as_ref().to_path_buf());
        self
    }

    /// Records read so far (also the index of the next one).
    pub fn records_read(&self) -> u64 {
        self.record
    }

    /// Decompressed bytes consumed so far (also the offset of the next record).
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Whether every LZ4 frame read so far announces a content checksum
    /// (known once the first record has been read). The decoder verifies
    /// each at its frame's end: a capture read to its end without error
    /// matched them all.
    pub fn has_content_checksum(&self) -> bool {
        let tap = self.decoder.get_ref();
        tap.frames > 0 && tap.flg_at.is_none() && tap.all_checksummed
    }

    /// LZ4 frames begun so far.
    pub fn lz4_frames(&self) -> u64 {
        self.decoder.get_ref().frames
    }

    /// Where the decoder stopped (the end of a frame, or of the input):
    /// finds the next frame and hands its magic number back to the
    /// decoder, skipping whole skippable frames; at the end of the input
    /// the content ends. A frame cut short, or bytes that begin no frame,
    /// are errors. Before the first frame, bytes that begin none are left
    /// to the decoder, whose error says what they are.
    fn next_frame(&mut self) -> Result<(), CaptureError> {
        let first = !self.started;
        self.started = true;
        if !first && self.decoder.get_ref().eof {
            let tap = self.decoder.get_ref();
            return Err(CaptureError::Unterminated { path: self.path.clone(), record: self.record, frame: tap.frames });
        }
        loop {
            let mut head = [0u8; 4];
            let got = read_full(&mut self.decoder.get_mut().inner, &mut head).map_err(|e| self.read_error(e))?;
            let magic = u32::from_le_bytes(head);
            if got == 0 {
                self.content_ended = true;
                return Ok(());
            } else if got == 4 && head == LZ4_MAGIC {
                self.decoder.get_mut().push_back(&head, true);
                return Ok(());
            } else if got == 4 && magic & !0xF == LZ4_SKIPPABLE_MAGIC {
                self.skip_skippable()?;
            } else if first {
                self.decoder.get_mut().push_back(&head[..got], false);
                return Ok(());
            } else {
                let tap = self.decoder.get_mut();
                let rest = io::copy(&mut tap.inner, &mut io::sink()).map_err(|e| self.read_error(e))?;
                let frame = self.decoder.get_ref().frames;
                return Err(CaptureError::TrailingBytes { path: self.path.clone(), record: self.record, bytes: got as u64 + rest, frame });
            }
        }
    }

    /// Skips a skippable frame whose magic number has been read: its
    /// length (u32, little-endian) and that many bytes.
    fn skip_skippable(&mut self) -> Result<(), CaptureError> {
        let cut = |r: &Self| CaptureError::Unterminated { path: r.path.clone(), record: r.record, frame: r.decoder.get_ref().frames + 1 };
        let tap = self.decoder.get_mut();
        let mut len = [0u8; 4];
        if read_full(&mut tap.inner, &mut len).map_err(|e| self.read_error(e))? < 4 {
            return Err(cut(self));
        }
        let want = u64::from(u32::from_le_bytes(len));
        let tap = self.decoder.get_mut();
        let skipped = io::copy(&mut (&mut tap.inner).take(want), &mut io::sink()).map_err(|e| self.read_error(e))?;
        if skipped < want {
            return Err(cut(self));
        }
        Ok(())
    }

    fn read_error(&self, e: io::Error) -> CaptureError {
        let (path, record, offset) = (self.path.clone(), self.record, self.offset);
        match lz4_flex::frame::Error::from(e) {
            lz4_flex::frame::Error::IoError(source) => CaptureError::Read { path, record, offset, source },
            source => CaptureError::Lz4 { path, record, offset, source },
        }
    }

    fn truncated(&self, needed: usize, found: usize) -> CaptureError {
        CaptureError::Truncated { path: self.path.clone(), record: self.record, offset: self.offset, needed, found }
    }

    /// The record layout found (known once the first record has been read).
    pub fn layout(&self) -> Option<RecordLayout> {
        self.layout
    }

    /// Fills `buf` from the decompressed content of the frames in turn (one
    /// stream across their boundaries); fewer bytes only at the end of the
    /// last frame.
    fn read_decoded(&mut self, buf: &mut [u8]) -> Result<usize, CaptureError> {
        if !self.started {
            self.next_frame()?;
        }
        let mut filled = 0;
        while filled < buf.len() && !self.content_ended {
            filled += read_full(&mut self.decoder, &mut buf[filled..]).map_err(|e| self.read_error(e))?;
            if filled < buf.len() {
                if let Err(e) = self.next_frame() {
                    self.boundary_error = Some(e);
                    self.content_ended = true;
                }
            }
        }
        Ok(filled)
    }

    /// Fills `buf` from the content: first what was read ahead, then the
    /// decoder.
    fn read_content(&mut self, buf: &mut [u8]) -> Result<usize, CaptureError> {
        let from_ahead = (self.ahead.len() - self.ahead_pos).min(buf.len());
        buf[..from_ahead].copy_from_slice(&self.ahead[self.ahead_pos..self.ahead_pos + from_ahead]);
        self.ahead_pos += from_ahead;
        if from_ahead == buf.len() {
            return Ok(from_ahead);
        }
        let got = from_ahead + self.read_decoded(&mut buf[from_ahead..])?;
        if got < buf.len() {
            if let Some(mut e) = self.boundary_error.take() {
                // Counted now: the records before it have all been read.
                if let CaptureError::TrailingBytes { record, .. } | CaptureError::Unterminated { record, .. } = &mut e {
                    *record = self.record;
                }
                return Err(e);
            }
        }
        Ok(got)
    }

    /// Skips up to `n` bytes of content; returns how many there were.
    fn skip_content(&mut self, n: usize) -> Result<usize, CaptureError> {
        let mut scratch = [0u8; 512];
        let mut skipped = 0;
        while skipped < n {
            let want = (n - skipped).min(scratch.len());
            let got = self.read_content(&mut scratch[..want])?;
            skipped += got;
            if got < want {
                break;
            }
        }
        Ok(skipped)
    }

    /// Reads the first two records' worth of content ahead and decides the
    /// layout (see the module docs).
    fn detect_layout(&mut self) -> Result<RecordLayout, CaptureError> {
        let mut ahead = vec![0u8; 2 * (DELAY_RECORD_HEADER_LEN + FRAME_LEN)];
        let got = self.read_decoded(&mut ahead)?;
        ahead.truncate(got);
        let layout = guess_layout(&ahead);
        self.ahead = ahead;
        self.ahead_pos = 0;
        Ok(layout)
    }

    /// Reads the next record; `Ok(None)` at a clean end of the content.
    pub fn read_record(&mut self) -> Result<Option<CaptureRecord>, CaptureError> {
        let layout = match self.layout {
            Some(l) => l,
            None => {
                let l = self.detect_layout()?;
                self.layout = Some(l);
                l
            }
        };
        let header_len = layout.header_len();
        let mut header = [0u8; DELAY_RECORD_HEADER_LEN];
        let got = self.read_content(&mut header[..header_len])?;
        if got == 0 {
            return Ok(None);
        }
        if got < header_len {
            return Err(self.truncated(header_len, got));
        }
        let time_ns = u64::from_be_bytes(header[0..8].try_into().expect("8 bytes"));
        let length = u16::from_be_bytes([header[8], header[9]]);
        let (dropped, delay_s) = match layout {
            RecordLayout::Dropped => (header[10], None),
            RecordLayout::Delay => (0, Some(f32::from_be_bytes(header[10..14].try_into().expect("4 bytes")))),
        };
        let needed = header_len + length as usize;

        if length as usize != FRAME_LEN {
            // Skip the payload so a reader may carry on past this record.
            let skipped = self.skip_content(length as usize)?;
            if skipped < length as usize {
                return Err(self.truncated(needed, header_len + skipped));
            }
            let err = CaptureError::WrongLength {
                path: self.path.clone(),
                record: self.record,
                offset: self.offset,
                length,
                expected: FRAME_LEN,
            };
            self.record += 1;
            self.offset += needed as u64;
            return Err(err);
        }

        let mut payload = [0u8; FRAME_LEN];
        let got = self.read_content(&mut payload)?;
        if got < FRAME_LEN {
            return Err(self.truncated(needed, header_len + got));
        }
        self.record += 1;
        self.offset += needed as u64;
        Ok(Some(CaptureRecord { time_ns, dropped, delay_s, payload }))
    }
}

/// The layout the first bytes of a capture's content fit (module docs).
fn guess_layout(ahead: &[u8]) -> RecordLayout {
    let length_at = |at: usize| ahead.get(at + 8..at + 10).map(|b| u16::from_be_bytes([b[0], b[1]]) as usize);
    let fits = |layout: RecordLayout| {
        let first = layout.header_len() + FRAME_LEN;
        length_at(0) == Some(FRAME_LEN)
            && match length_at(first) {
                Some(n) => n == FRAME_LEN,
                // One record (or a second one cut short): its size decides.
                None => ahead.len() == first,
            }
    };
    let checksum_ok = |layout: RecordLayout| {
        let h = layout.header_len();
        ahead.get(h..h + FRAME_LEN).is_some_and(|p| {
            let bytes: &[u8; FRAME_LEN] = p.try_into().expect("one frame");
            ItpFrame::parse(&ItpView::new_unchecked(bytes)).is_ok()
        })
    };
    match (fits(RecordLayout::Dropped), fits(RecordLayout::Delay)) {
        (false, true) => RecordLayout::Delay,
        (true, true) if !checksum_ok(RecordLayout::Dropped) && checksum_ok(RecordLayout::Delay) => RecordLayout::Delay,
        // Anything else reads as netfi's own layout, whose errors then say
        // what is wrong.
        _ => RecordLayout::Dropped,
    }
}

impl<R: Read> Iterator for CaptureReader<R> {
    type Item = Result<CaptureRecord, CaptureError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.read_record() {
            Ok(Some(record)) => Some(Ok(record)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => {
                self.done = !matches!(e, CaptureError::WrongLength { .. });
                Some(Err(e))
            }
        }
    }
}

/// Writes a capture: records into an LZ4 frame, and into a new one after
/// each [`CaptureWriter::end_frame`]. Call [`CaptureWriter::finish`] to
/// close the last frame; a writer dropped without it leaves a truncated
/// file.
pub struct CaptureWriter<W: Write> {
    /// Always present but while [`CaptureWriter::end_frame`] swaps frames
    /// (and after it failed).
    encoder: Option<FrameEncoder<W>>,
    path: Option<PathBuf>,
    record: u64,
}

impl CaptureWriter<BufWriter<File>> {
    /// Creates (or truncates) a capture file.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, CaptureError> {
        let path = path.as_ref();
        let file = File::create(path)
            .map_err(|source| CaptureError::Open { path: Some(path.to_path_buf()), source })?;
        Ok(CaptureWriter::new(BufWriter::new(file)).with_path(path))
    }
}

impl<W: Write> CaptureWriter<W> {
    /// Writes a capture into a stream, with the LZ4 content checksum.
    pub fn new(writer: W) -> Self {
        CaptureWriter { encoder: Some(Self::frame(writer)), path: None, record: 0 }
    }

    fn frame(writer: W) -> FrameEncoder<W> {
        FrameEncoder::with_frame_info(lz4_flex::frame::FrameInfo::new().content_checksum(true), writer)
    }

    /// Closes the current LZ4 frame (its end mark and content checksum),
    /// flushes it to the stream, and starts the next: what is written up to
    /// here is a complete capture on its own, as a recorder that flushes
    /// every batch of records leaves it.
    pub fn end_frame(&mut self) -> Result<(), CaptureError> {
        let encoder = self.encoder.take().ok_or_else(|| self.write_error(io::Error::other("an earlier end_frame failed")))?;
        let mut inner = encoder.finish().map_err(|e| self.write_error(e.into()))?;
        inner.flush().map_err(|e| self.write_error(e))?;
        self.encoder = Some(Self::frame(inner));
        Ok(())
    }

    /// Writes `bytes` into the current frame.
    fn put(&mut self, bytes: &[u8]) -> Result<(), CaptureError> {
        let written = match self.encoder.as_mut() {
            Some(e) => e.write_all(bytes),
            None => Err(io::Error::other("an earlier end_frame failed")),
        };
        written.map_err(|e| self.write_error(e))
    }

    /// Names the stream's file in error messages.
    pub fn with_path(mut self, path: impl AsRef<Path>) -> Self {
        self.path = Some(path.as_ref().to_path_buf());
        self
    }

    /// Records written so far.
    pub fn records_written(&self) -> u64 {
        self.record
    }

    fn write_error(&self, source: io::Error) -> CaptureError {
        CaptureError::Write { path: self.path.clone(), record: self.record, source }
    }

    /// Appends one record.
    pub fn write_record(&mut self, record: &CaptureRecord) -> Result<(), CaptureError> {
        let mut bytes = [0u8; RECORD_LEN];
        bytes[0..8].copy_from_slice(&record.time_ns.to_be_bytes());
        bytes[8..10].copy_from_slice(&(FRAME_LEN as u16).to_be_bytes());
        bytes[10] = record.dropped;
        bytes[RECORD_HEADER_LEN..].copy_from_slice(&record.payload);
        self.put(&bytes)?;
        self.record += 1;
        Ok(())
    }

    /// Appends a record of a delivered frame received at `time_ns`.
    pub fn write_frame(&mut self, time_ns: u64, frame: &ItpFrame) -> Result<(), CaptureError> {
        self.write_record(&CaptureRecord::new(time_ns, frame))
    }

    /// Appends a record with an arbitrary payload, for payloads that are not
    /// ITP frames (readers of this crate reject them; tests use it to build
    /// malformed captures).
    pub fn write_raw(&mut self, time_ns: u64, dropped: u8, payload: &[u8]) -> Result<(), CaptureError> {
        let length = u16::try_from(payload.len()).map_err(|_| CaptureError::PayloadTooLong {
            path: self.path.clone(),
            record: self.record,
            length: payload.len(),
        })?;
        let mut header = [0u8; RECORD_HEADER_LEN];
        header[0..8].copy_from_slice(&time_ns.to_be_bytes());
        header[8..10].copy_from_slice(&length.to_be_bytes());
        header[10] = dropped;
        self.put(&header)?;
        self.put(payload)?;
        self.record += 1;
        Ok(())
    }

    /// Appends a record in the delay layout ([`RecordLayout::Delay`]): the
    /// frame and the delay drawn for it. A capture must not mix layouts.
    pub fn write_delay_record(&mut self, time_ns: u64, delay_s: f32, payload: &[u8; FRAME_LEN]) -> Result<(), CaptureError> {
        let mut bytes = [0u8; DELAY_RECORD_HEADER_LEN + FRAME_LEN];
        bytes[0..8].copy_from_slice(&time_ns.to_be_bytes());
        bytes[8..10].copy_from_slice(&(FRAME_LEN as u16).to_be_bytes());
        bytes[10..14].copy_from_slice(&delay_s.to_be_bytes());
        bytes[DELAY_RECORD_HEADER_LEN..].copy_from_slice(payload);
        self.put(&bytes)?;
        self.record += 1;
        Ok(())
    }

    /// Closes the last LZ4 frame, flushes, and returns the underlying writer.
    pub fn finish(self) -> Result<W, CaptureError> {
        let path = self.path;
        let record = self.record;
        let encoder = self
            .encoder
            .ok_or_else(|| CaptureError::Write { path: path.clone(), record, source: io::Error::other("an earlier end_frame failed") })?;
        let mut inner = encoder.finish().map_err(|e| CaptureError::Write { path: path.clone(), record, source: e.into() })?;
        inner.flush().map_err(|source| CaptureError::Write { path, record, source })?;
        Ok(inner)
    }
}

/// Summary of a capture, built record by record with [`CaptureStats::push`].
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct CaptureStats {
    /// Records (frames).
    pub frames: u64,
    /// Time of the first record, ns.
    pub first_ns: u64,
    /// Time of the last record, ns.
    pub last_ns: u64,
    /// Longest interval between consecutive records, ns.
    pub gap_ns_max: u64,
    /// Records stamped earlier than the one before them (a wall clock may step
    /// back); such intervals count as zero in `gap_ns_max`.
    pub time_steps_backward: u64,
    /// Frames whose carried checksum disagrees with their fields.
    pub checksum_failures: u64,
    /// Frames whose `surgeon_mode` is not engaged (1): their increments do
    /// not apply.
    pub clutch_released_frames: u64,
    /// Records whose dropped flag is set.
    pub dropped_flagged: u64,
    /// Longest step backwards in time, ns.
    #[serde(default)]
    pub step_backward_ns_max: u64,
    /// Steps backwards longer than [`MAX_STEP_BACKWARD_NS`].
    #[serde(default)]
    pub steps_backward_over_limit: u64,
    /// Gaps forwards longer than [`MAX_GAP_NS`].
    #[serde(default)]
    pub gaps_over_limit: u64,
    /// Whether every LZ4 frame of the file carries a content checksum (set
    /// by [`load`] and [`parse`]; a loaded capture matched them).
    #[serde(default)]
    pub content_checksum: bool,
    /// The LZ4 frames the file holds (set by [`load`] and [`parse`]; a
    /// recorder that flushes every batch writes one per batch).
    #[serde(default)]
    pub lz4_frames: u64,
}

impl CaptureStats {
    /// Accounts for one more record.
    pub fn push(&mut self, record: &CaptureRecord) {
        if self.frames == 0 {
            self.first_ns = record.time_ns;
        } else if record.time_ns < self.last_ns {
            let back = self.last_ns - record.time_ns;
            self.time_steps_backward += 1;
            self.step_backward_ns_max = self.step_backward_ns_max.max(back);
            self.steps_backward_over_limit += u64::from(back > MAX_STEP_BACKWARD_NS);
        } else {
            let gap = record.time_ns - self.last_ns;
            self.gap_ns_max = self.gap_ns_max.max(gap);
            self.gaps_over_limit += u64::from(gap > MAX_GAP_NS);
        }
        self.last_ns = record.time_ns;
        self.frames += 1;
        let view = record.view();
        if !view.verify_checksum() {
            self.checksum_failures += 1;
        }
        if view.surgeon_mode() != SURGEON_ENGAGED {
            self.clutch_released_frames += 1;
        }
        if record.is_dropped() {
            self.dropped_flagged += 1;
        }
    }

    /// Statistics of a slice of records.
    pub fn from_records(records: &[CaptureRecord]) -> CaptureStats {
        let mut stats = CaptureStats::default();
        records.iter().for_each(|r| stats.push(r));
        stats
    }

    /// Why a capture with these counts is refused, by the rule in the
    /// module docs; `None` when it is accepted.
    pub fn refusal(&self) -> Option<String> {
        let mut why = Vec::new();
        if self.checksum_failures > 0 && !self.content_checksum {
            why.push(format!(
                "{} of {} frames have a wrong ITP checksum and the file has no LZ4 content checksum to show it is intact",
                self.checksum_failures, self.frames
            ));
        }
        if self.steps_backward_over_limit > 0 {
            why.push(format!(
                "{} time step(s) backwards of more than {} s (longest {:.3} s)",
                self.steps_backward_over_limit,
                MAX_STEP_BACKWARD_NS / 1_000_000_000,
                self.step_backward_ns_max as f64 * 1e-9
            ));
        }
        if self.gaps_over_limit > 0 {
            why.push(format!(
                "{} gap(s) of more than {} s between records (longest {:.3} s)",
                self.gaps_over_limit,
                MAX_GAP_NS / 1_000_000_000,
                self.gap_ns_max as f64 * 1e-9
            ));
        }
        (!why.is_empty()).then(|| why.join("; "))
    }

    /// What is accepted but worth saying, one line each.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.checksum_failures > 0 && self.content_checksum {
            w.push(format!("{} frames were recorded with a wrong ITP checksum", self.checksum_failures));
        }
        if self.time_steps_backward > 0 && self.steps_backward_over_limit == 0 {
            w.push(format!(
                "{} time step(s) backwards (longest {:.6} s); replayed as no wait",
                self.time_steps_backward,
                self.step_backward_ns_max as f64 * 1e-9
            ));
        }
        w
    }

    /// Time from the first record to the last, ns.
    pub fn duration_ns(&self) -> u64 {
        self.last_ns.saturating_sub(self.first_ns)
    }

    /// Time from the first record to the last, s.
    pub fn duration_s(&self) -> f64 {
        self.duration_ns() as f64 * 1e-9
    }

    /// Mean frame rate, Hz: intervals per second, `(frames − 1) / duration`;
    /// 0 with fewer than two frames or no elapsed time.
    pub fn rate_hz_mean(&self) -> f64 {
        if self.frames < 2 || self.duration_ns() == 0 {
            0.0
        } else {
            (self.frames - 1) as f64 / self.duration_s()
        }
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
mod tests {
    use super::*;
    use crate::frame::SURGEON_DISENGAGED;

    fn frame(sequence: u32, surgeon_mode: i32) -> ItpFrame {
        ItpFrame { sequence, delx: [3, -1], qw: [1.0, 1.0], surgeon_mode, ..ItpFrame::default() }.with_checksum()
    }

    fn capture_bytes(records: &[CaptureRecord]) -> Vec<u8> {
        let mut w = CaptureWriter::new(Vec::new());
        for r in records {
            w.write_record(r).unwrap();
        }
        w.finish().unwrap()
    }

    fn lz4(content: &[u8]) -> Vec<u8> {
        let mut enc = FrameEncoder::new(Vec::new());
        enc.write_all(content).unwrap();
        enc.finish().unwrap()
    }

    #[test]
    fn a_replayed_delay_capture_names_the_layout_read() {
        // The replay stage (in the core, which does not read captures)
        // describes its recording in this reader's words.
        assert_eq!(crate::model::RecordingKind::DelayCapture.layout(), RecordLayout::Delay.describe());
    }

    #[test]
    fn errors_can_cross_threads() {
        fn send_sync<T: Send + Sync + 'static>() {}
        send_sync::<CaptureError>();
    }

    fn delay_capture(n: u32) -> Vec<u8> {
        let mut w = CaptureWriter::new(Vec::new());
        for i in 0..n {
            w.write_delay_record(1_000 * u64::from(i), 0.25 + i as f32 * 1e-3, &frame(i, 1).to_bytes()).unwrap();
        }
        w.finish().unwrap()
    }

    #[test]
    fn both_record_layouts_are_read_and_told_apart() {
        for n in [1u32, 2, 50] {
            let cap = parse(&delay_capture(n)).unwrap();
            assert_eq!(cap.layout, RecordLayout::Delay, "{n} records");
            assert_eq!(cap.records.len(), n as usize);
            assert_eq!(cap.records[n as usize - 1].delay_s, Some(0.25 + (n - 1) as f32 * 1e-3));
            assert_eq!(cap.records[0].frame().unwrap().sequence, 0);
            let plain = parse(&capture_bytes(&[CaptureRecord::new(5, &frame(1, 1)); 3][..n.min(3) as usize])).unwrap();
            assert_eq!(plain.layout, RecordLayout::Dropped);
            assert_eq!(plain.records[0].delay_s, None);
        }
    }

    #[test]
    fn writer_reader_round_trip() {
        let records: Vec<_> = (0..1000u32)
            .map(|i| CaptureRecord {
                time_ns: 1_000_000 * i as u64 + 7,
                dropped: (i % 3) as u8,
                delay_s: None,
                payload: frame(i, (i % 5 != 0) as i32).to_bytes(),
            })
            .collect();
        let bytes = capture_bytes(&records);
        let back: Vec<_> = CaptureReader::new(&bytes[..]).collect::<Result<_, _>>().unwrap();
        assert_eq!(back, records);
    }

    #[test]
    fn record_layout_is_big_endian_header_then_payload() {
        let r = CaptureRecord::new(0x0102_0304_0506_0708, &frame(9, 1));
        let bytes = capture_bytes(&[r]);
        let mut content = Vec::new();
        FrameDecoder::new(&bytes[..]).read_to_end(&mut content).unwrap();
        assert_eq!(content.len(), RECORD_LEN);
        assert_eq!(&content[..11], &[1, 2, 3, 4, 5, 6, 7, 8, 0, 124, 0]);
        assert_eq!(&content[11..], &r.payload[..]);
    }

    #[test]
    fn stats_count_what_they_say() {
        let mut bad = frame(3, 1);
        bad.checksum += 1;
        let records = [
            CaptureRecord::new(1_000, &frame(0, 1)),
            CaptureRecord::new(3_000, &frame(1, SURGEON_DISENGAGED)),
            CaptureRecord::new(2_500, &frame(2, 1)),
            CaptureRecord { dropped: 1, ..CaptureRecord::new(10_000, &bad) },
        ];
        let s = CaptureStats::from_records(&records);
        assert_eq!(s.frames, 4);
        assert_eq!(s.duration_ns(), 9_000);
        assert_eq!(s.gap_ns_max, 7_500);
        assert_eq!(s.time_steps_backward, 1);
        assert_eq!(s.checksum_failures, 1);
        assert_eq!(s.clutch_released_frames, 1);
        assert_eq!(s.dropped_flagged, 1);
        assert!((s.rate_hz_mean() - 3.0 / 9e-6).abs() < 1e-6);
    }

    #[test]
    fn wrong_length_names_record_and_offset_and_reading_goes_on() {
        let mut w = CaptureWriter::new(Vec::new());
        w.write_frame(1, &frame(0, 1)).unwrap();
        w.write_raw(2, 0, &[0u8; 100]).unwrap();
        w.write_frame(3, &frame(2, 1)).unwrap();
        let bytes = w.finish().unwrap();
        let items: Vec<_> = CaptureReader::new(&bytes[..]).collect();
        assert_eq!(items.len(), 3);
        match &items[1] {
            Err(CaptureError::WrongLength { record: 1, offset, length: 100, expected: 124, .. }) => {
                assert_eq!(*offset, RECORD_LEN as u64)
            }
            other => panic!("expected WrongLength, got {other:?}"),
        }
        assert_eq!(items[2].as_ref().unwrap().time_ns, 3);
        let msg = items[1].as_ref().unwrap_err().to_string();
        assert!(msg.contains("record 1 at byte 135") && msg.contains("payload length 100"), "{msg}");
    }

    #[test]
    fn truncated_tail_is_an_error() {
        let mut content = Vec::new();
        for i in 0..3u32 {
            content.extend_from_slice(&(i as u64).to_be_bytes());
            content.extend_from_slice(&124u16.to_be_bytes());
            content.push(0);
            content.extend_from_slice(&frame(i, 1).to_bytes());
        }
        // Cut inside the payload of the last record.
        let cut = &content[..2 * RECORD_LEN + 50];
        let items: Vec<_> = CaptureReader::new(&lz4(cut)[..]).collect();
        assert_eq!(items.len(), 3);
        match &items[2] {
            Err(CaptureError::Truncated { record: 2, offset, needed: 135, found: 50, .. }) => {
                assert_eq!(*offset, 2 * RECORD_LEN as u64)
            }
            other => panic!("expected Truncated, got {other:?}"),
        }
        // Cut inside a header.
        let items: Vec<_> = CaptureReader::new(&lz4(&content[..RECORD_LEN + 5])[..]).collect();
        assert!(matches!(items[1], Err(CaptureError::Truncated { record: 1, needed: 11, found: 5, .. })));
    }

    #[test]
    fn not_lz4_is_an_error() {
        let items: Vec<_> = CaptureReader::new(&b"definitely not an lz4 frame"[..]).collect();
        assert_eq!(items.len(), 1);
        assert!(
            matches!(items[0], Err(CaptureError::Lz4 { record: 0, offset: 0, .. })),
            "{:?}",
            items[0]
        );
    }

    #[test]
    fn errors_name_the_path() {
        let dir = std::env::temp_dir().join(format!("netfi-capture-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cut.bin");
        let mut content = vec![0u8; RECORD_HEADER_LEN];
        content[9] = FRAME_LEN as u8;
        content.extend_from_slice(&frame(0, 1).to_bytes());
        content.extend_from_slice(&[0u8; 5]);
        std::fs::write(&path, lz4(&content)).unwrap();
        let err = load(&path).unwrap_err();
        assert!(err.to_string().contains("cut.bin") && err.to_string().contains("record 1"), "{err}");

        let empty = dir.join("empty.bin");
        CaptureWriter::create(&empty).unwrap().finish().unwrap();
        assert!(matches!(load(&empty), Err(CaptureError::Empty { .. })));

        let missing = dir.join("missing.bin");
        let err = load(&missing).unwrap_err();
        assert!(matches!(err, CaptureError::Open { .. }) && err.to_string().contains("missing.bin"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `n` records written in frames of `batch` records, each frame closed
    /// with its end mark and content checksum.
    fn batched(n: u32, batch: u32) -> (Vec<CaptureRecord>, Vec<u8>) {
        let records: Vec<_> = (0..n).map(|i| CaptureRecord::new(1_000 + u64::from(i) * 2_000_000, &frame(i, 1))).collect();
        let mut w = CaptureWriter::new(Vec::new());
        for (i, r) in records.iter().enumerate() {
            if i > 0 && i as u32 % batch == 0 {
                w.end_frame().unwrap();
            }
            w.write_record(r).unwrap();
        }
        (records, w.finish().unwrap())
    }

    #[test]
    fn a_capture_written_in_batches_is_one_stream_of_records() {
        // 2 500 records in frames of 1 000 (and of 7, and of 1: records
        // never span a frame here, but may below): every record, in order.
        for batch in [1_000, 7, 1] {
            let (records, bytes) = batched(2_500, batch);
            let cap = parse(&bytes).unwrap();
            assert_eq!(cap.records, records, "batches of {batch}");
            assert_eq!(cap.stats.lz4_frames, u64::from(2_500u32.div_ceil(batch)));
            assert!(cap.stats.content_checksum);
            // `lz4 -d` decodes the same bytes as one stream; the LZ4
            // decoder stops at each frame's end and goes on when asked again.
            let (mut content, mut decoder) = (Vec::new(), FrameDecoder::new(&bytes[..]));
            while decoder.read_to_end(&mut content).unwrap() > 0 {}
            assert_eq!(content.len(), 2_500 * RECORD_LEN);
        }
        // A record cut across two frames, and an empty frame between: the
        // content is one stream.
        let (records, _) = batched(3, 3);
        let mut content = Vec::new();
        for r in &records {
            let mut w = CaptureWriter::new(Vec::new());
            w.write_record(r).unwrap();
            let one = w.finish().unwrap();
            FrameDecoder::new(&one[..]).read_to_end(&mut content).unwrap();
        }
        let mut bytes = lz4(&content[..RECORD_LEN + 50]);
        bytes.extend(lz4(&[]));
        bytes.extend(lz4(&content[RECORD_LEN + 50..]));
        let cap = parse(&bytes).unwrap();
        assert_eq!(cap.records, records);
        assert_eq!(cap.stats.lz4_frames, 3);
        assert!(!cap.stats.content_checksum, "frames without a content checksum");
    }

    #[test]
    fn only_complete_frames_are_a_capture() {
        let (_, bytes) = batched(30, 10);
        let frame_len = batched(10, 10).1.len();
        // Garbage between two frames, and after the last.
        let mut between = bytes[..frame_len].to_vec();
        between.extend_from_slice(b"garbage!");
        between.extend_from_slice(&bytes[frame_len..]);
        match parse(&between) {
            Err(e @ CaptureError::TrailingBytes { record: 10, frame: 1, .. }) => {
                assert!(e.to_string().contains("after the end of LZ4 frame 1 (after record 10)"), "{e}")
            }
            other => panic!("expected TrailingBytes, got {other:?}"),
        }
        let mut after = bytes.clone();
        after.extend_from_slice(&[0, 1, 2]);
        assert!(matches!(parse(&after), Err(CaptureError::TrailingBytes { record: 30, frame: 3, bytes: 3, .. })));
        // The first frame cut short (at its end mark), the others whole: the
        // second frame's magic number is not the first's end mark.
        let mut cut = bytes[..frame_len - 8].to_vec();
        cut.extend_from_slice(&bytes[frame_len..]);
        assert!(parse(&cut).is_err());
        // The last frame cut short at a block boundary (its end mark gone),
        // and a lone magic number after a whole frame.
        assert!(matches!(parse(&bytes[..bytes.len() - 8]), Err(CaptureError::Unterminated { record: 30, frame: 3, .. })));
        let mut magic = bytes[..frame_len].to_vec();
        magic.extend_from_slice(&LZ4_MAGIC);
        assert!(matches!(parse(&magic), Err(CaptureError::Unterminated { record: 10, frame: 2, .. })));
        // A bad content checksum in the middle frame.
        let mut bad = bytes.clone();
        bad[2 * frame_len - 1] ^= 1;
        assert!(matches!(parse(&bad), Err(CaptureError::Lz4 { .. })), "{:?}", parse(&bad).map(|c| c.stats));
    }

    #[test]
    fn skippable_frames_are_skipped_when_whole() {
        let (records, bytes) = batched(20, 10);
        let frame_len = batched(10, 10).1.len();
        let skippable = |len: u32| {
            let mut s = vec![0x5a, 0x2a, 0x4d, 0x18];
            s.extend_from_slice(&len.to_le_bytes());
            s.extend(std::iter::repeat_n(7u8, len as usize));
            s
        };
        let mut with = skippable(5);
        with.extend_from_slice(&bytes[..frame_len]);
        with.extend(skippable(0));
        with.extend_from_slice(&bytes[frame_len..]);
        with.extend(skippable(3));
        assert_eq!(parse(&with).unwrap().records, records);
        let mut cut = bytes.clone();
        cut.extend_from_slice(&skippable(9)[..12]);
        assert!(matches!(parse(&cut), Err(CaptureError::Unterminated { record: 20, .. })));
    }

    #[test]
    fn payload_too_long_is_an_error() {
        let mut w = CaptureWriter::new(Vec::new());
        assert!(matches!(
            w.write_raw(0, 0, &vec![0u8; 70_000]),
            Err(CaptureError::PayloadTooLong { length: 70_000, record: 0, .. })
        ));
    }
}
