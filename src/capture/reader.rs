//! Streaming a capture's records out of its LZ4 frames.

use super::{CaptureError, CaptureRecord, RecordLayout, DELAY_RECORD_HEADER_LEN};
use crate::frame::{ItpFrame, ItpView, FRAME_LEN};
use lz4_flex::frame::FrameDecoder;
use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::{Path, PathBuf};

/// The LZ4 frame format's magic number, little-endian on the wire.
pub const LZ4_MAGIC: [u8; 4] = [0x04, 0x22, 0x4d, 0x18];
/// The magic numbers of LZ4's skippable frames, `0x184D2A50`–`0x184D2A5F`,
/// without their low four bits.
const LZ4_SKIPPABLE_MAGIC: u32 = 0x184D_2A50;
/// Bit of the frame descriptor's FLG byte (the fifth byte of a frame) that
/// announces a content checksum.
const LZ4_FLG_CONTENT_CHECKSUM: u8 = 0x04;

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

/// The file under the decoder, counting the bytes taken from it.
struct Counting<R> {
    inner: R,
    /// Bytes read from `inner` so far.
    bytes_read: u64,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.bytes_read += n as u64;
        Ok(n)
    }
}

/// The compressed stream under the decoder: counts what the decoder has
/// taken, hands back bytes the reader looked at ahead (the magic number of
/// the next frame), and notes each frame's FLG byte as it goes by.
struct Tap<R> {
    inner: Counting<R>,
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
        Tap { inner: Counting { inner, bytes_read: 0 }, consumed: 0, back: [0; 4], back_len: 0, back_pos: 0, flg_at: None, frames: 0, all_checksummed: true, eof: false }
    }

    /// Where the decoder is in the file: the bytes read from it, less
    /// those read ahead and not yet handed over.
    fn file_offset(&self) -> u64 {
        self.inner.bytes_read - u64::from(self.back_len - self.back_pos)
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
    /// The most records read; the next one is refused.
    max_records: u64,
    /// The last frame has ended and nothing follows: the decoder is not
    /// asked again.
    content_ended: bool,
    /// What ended the content early (bytes that begin no frame, a frame cut
    /// short), found when the content read ahead reached it: given once
    /// the records before it have been read.
    boundary_error: Option<CaptureError>,
}

impl CaptureReader<BufReader<File>> {
    /// Opens a capture file: a regular file only ([`crate::load::open_regular`];
    /// a FIFO or a device is refused, not waited on).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, CaptureError> {
        let path = path.as_ref();
        let file = crate::load::open_regular(path)
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
            max_records: u64::MAX,
            content_ended: false,
            boundary_error: None,
        }
    }

    /// Names the stream's file in error messages.
    pub fn with_path(mut self, path: impl AsRef<Path>) -> Self {
        self.path = Some(path.as_ref().to_path_buf());
        self
    }

    /// The file named in error messages, if any.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Reads at most `max_records` records: a record beyond them is
    /// [`CaptureError::TooManyRecords`] as soon as its first byte is read
    /// (default: no limit; a reader keeps nothing per record).
    pub fn with_max_records(mut self, max_records: u64) -> Self {
        self.max_records = max_records;
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
        if e.kind() == io::ErrorKind::UnexpectedEof {
            // The decoder wanted bytes of a frame (its header, a block, a
            // checksum) that the file does not have.
            // A file cut inside its first magic number has begun no frame
            // yet: it is cut in the first.
            let tap = self.decoder.get_ref();
            return CaptureError::Cut { path, record, frame: tap.frames.max(1), file_bytes: tap.file_offset() };
        }
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
        if self.record >= self.max_records {
            return Err(CaptureError::TooManyRecords { path: self.path.clone(), max_records: self.max_records });
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
