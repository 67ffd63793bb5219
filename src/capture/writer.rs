//! Writing a capture, every LZ4 frame with its content checksum.

use super::{CaptureError, CaptureRecord, DELAY_RECORD_HEADER_LEN, RECORD_HEADER_LEN, RECORD_LEN};
use crate::frame::{ItpFrame, FRAME_LEN};
use lz4_flex::frame::FrameEncoder;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

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
