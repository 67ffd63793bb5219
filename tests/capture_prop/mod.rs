//! Property-based tests of the capture reader (`netfi::capture::parse`, the
//! same path as `load`): whatever the bytes, reading never panics, a
//! damaged capture is classified by the rule in `src/capture.rs`'s docs,
//! and captures concatenated (a sequence of LZ4 frames) are one capture.
//!
//! Each property runs 1,000 cases by default (6,000 in all); set
//! `PROPTEST_CASES` for a longer run, as in the README.

use lz4_flex::frame::FrameEncoder;
use netfi::capture::{self, CaptureError, CaptureRecord, CaptureWriter, RECORD_HEADER_LEN, RECORD_LEN};
use netfi::frame::{ItpFrame, ItpView};
use proptest::prelude::*;
use std::io::{Read, Write};

fn config() -> ProptestConfig {
    // PROPTEST_CASES, when set, wins over the 1,000 default.
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    ProptestConfig { cases, failure_persistence: None, ..ProptestConfig::default() }
}

/// `n` records, 1 ms apart from `t0`, with varied fields.
fn records(n: usize, t0: u64, seed: i32) -> Vec<CaptureRecord> {
    (0..n)
        .map(|i| {
            let k = i as i32;
            let f = ItpFrame {
                sequence: 1000 + i as u32,
                delx: [k.wrapping_mul(seed), -k],
                dely: [seed, k],
                delz: [k ^ seed, 3],
                qw: [1.0, 1.0],
                grasp: [k, -k],
                surgeon_mode: 1,
                ..ItpFrame::default()
            }
            .with_checksum();
            CaptureRecord::new(t0 + i as u64 * 1_000_000, &f)
        })
        .collect()
}

/// A capture as this crate writes it: with the LZ4 content checksum.
fn checksummed(recs: &[CaptureRecord]) -> Vec<u8> {
    let mut w = CaptureWriter::new(Vec::new());
    recs.iter().for_each(|r| w.write_record(r).unwrap());
    w.finish().unwrap()
}

/// The decompressed records.
fn content(recs: &[CaptureRecord]) -> Vec<u8> {
    let mut c = Vec::new();
    for r in recs {
        c.extend_from_slice(&r.time_ns.to_be_bytes());
        c.extend_from_slice(&124u16.to_be_bytes());
        c.push(r.dropped);
        c.extend_from_slice(&r.payload);
    }
    c
}

/// Content compressed without a content checksum, as the shipped capture is.
fn unchecksummed(content: &[u8]) -> Vec<u8> {
    let mut e = FrameEncoder::new(Vec::new());
    e.write_all(content).unwrap();
    e.finish().unwrap()
}

proptest! {
    #![proptest_config(config())]

    /// Any bytes at all: an error or a capture, never a panic; a capture
    /// that is accepted is consistent with its own statistics.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048), lz4_prefix in any::<bool>()) {
        let mut input = Vec::new();
        if lz4_prefix {
            // Get past the magic number more often than chance would.
            input.extend_from_slice(&[0x04, 0x22, 0x4d, 0x18]);
        }
        input.extend_from_slice(&bytes);
        if let Ok(cap) = capture::parse(&input) {
            prop_assert!(!cap.records.is_empty());
            prop_assert_eq!(cap.stats.frames, cap.records.len() as u64);
            prop_assert!(cap.stats.refusal().is_none());
        }
    }

    /// One flipped bit anywhere in a checksummed file: refused, or (a bit
    /// the format does not use) exactly the same records.
    #[test]
    fn a_flipped_bit_in_a_checksummed_file_is_refused_or_harmless(n in 1usize..40, seed in any::<i32>(), pos in any::<prop::sample::Index>(), bit in 0u8..8) {
        let recs = records(n, 1_700_000_000_000_000_000, seed);
        let mut bytes = checksummed(&recs);
        let at = pos.index(bytes.len());
        bytes[at] ^= 1 << bit;
        match capture::parse(&bytes) {
            Ok(cap) => prop_assert_eq!(cap.records, recs, "byte {} bit {} changed the records unnoticed", at, bit),
            Err(_) => {}
        }
    }

    /// Garbage after the last LZ4 frame, or between two, is refused and
    /// counted (an LZ4 magic number is another frame, not garbage).
    #[test]
    fn garbage_after_or_between_frames_is_refused(n in 1usize..20, garbage in proptest::collection::vec(any::<u8>(), 1..300), between in any::<bool>()) {
        prop_assume!(!garbage.starts_with(&[0x04, 0x22, 0x4d, 0x18]));
        prop_assume!(!(garbage.len() >= 4 && u32::from_le_bytes([garbage[0], garbage[1], garbage[2], garbage[3]]) & !0xF == 0x184D_2A50));
        let recs = records(n, 5_000_000_000, 7);
        let mut bytes = checksummed(&recs);
        bytes.extend_from_slice(&garbage);
        if between {
            bytes.extend_from_slice(&checksummed(&records(3, 5_000_000_000 + n as u64 * 1_000_000, 8)));
        }
        match capture::parse(&bytes) {
            Err(CaptureError::TrailingBytes { bytes: b, record, frame, .. }) => {
                prop_assert_eq!(b, (bytes.len() - checksummed(&recs).len()) as u64);
                prop_assert_eq!(record, n as u64);
                prop_assert_eq!(frame, 1);
            }
            other => prop_assert!(false, "expected TrailingBytes, got {:?}", other.map(|c| c.stats)),
        }
    }

    /// Captures concatenated (with or without a content checksum each) are
    /// one capture: every record of both, in order, when their times
    /// follow on; refused by the time rule when the second starts more than
    /// 60 s after, or more than 1 s before, the first ends.
    #[test]
    fn concatenated_captures_are_one_stream(a in 1usize..20, b in 1usize..20, t_a in 0u64..1u64 << 62, step_ns in -2_000_000_000i64..70_000_000_000, check_b in any::<bool>()) {
        let first = records(a, t_a, 1);
        let last_a = first[a - 1].time_ns;
        let t_b = last_a.saturating_add_signed(step_ns);
        let second = records(b, t_b, 2);
        let mut bytes = checksummed(&first);
        bytes.extend_from_slice(&if check_b { checksummed(&second) } else { unchecksummed(&content(&second)) });
        let step = t_b as i128 - last_a as i128;
        match capture::parse(&bytes) {
            Ok(cap) => {
                prop_assert!(step >= -1_000_000_000 && step <= 60_000_000_000, "step {} accepted", step);
                prop_assert_eq!(cap.records, [first, second].concat());
                prop_assert_eq!(cap.stats.lz4_frames, 2);
                prop_assert_eq!(cap.stats.content_checksum, check_b);
            }
            Err(CaptureError::Damaged { .. }) => prop_assert!(!(-1_000_000_000..=60_000_000_000).contains(&step), "step {} refused", step),
            Err(e) => prop_assert!(false, "{}", e),
        }
    }

    /// A flipped bit in the records of a file *without* a content checksum
    /// (as the shipped capture is): a frame whose ITP checksum breaks is
    /// refused; a time stamp moved by 2^40 ns (18 min) or more is refused;
    /// a wrong length is refused; nothing panics.
    #[test]
    fn a_flipped_bit_in_an_unchecksummed_file_is_classified(n in 2usize..40, seed in any::<i32>(), rec in any::<prop::sample::Index>(), off in 0usize..RECORD_LEN, bit in 0u8..8) {
        let recs = records(n, 1_700_000_000_000_000_000, seed);
        let mut c = content(&recs);
        let r = rec.index(n);
        let at = r * RECORD_LEN + off;
        c[at] ^= 1 << bit;
        let result = capture::parse(&unchecksummed(&c));
        match off {
            // The time stamp, big-endian: byte k holds bits 8·(7−k)..
            0..=7 => {
                let bit_no = 8 * (7 - off) + bit as usize;
                if bit_no >= 40 {
                    prop_assert!(matches!(result, Err(CaptureError::Damaged { .. })), "time bit {}: {:?}", bit_no, result.map(|c| c.stats));
                } else if bit_no < 20 {
                    // Under 1 ms: a plausible time, accepted (and undetectable).
                    prop_assert!(result.is_ok(), "time bit {}: {:?}", bit_no, result.err());
                }
            }
            8 | 9 => prop_assert!(result.is_err(), "length flipped, accepted"),
            10 => {
                let cap = result.unwrap();
                prop_assert_eq!(cap.stats.dropped_flagged, 1);
            }
            _ => {
                let payload = &c[r * RECORD_LEN + RECORD_HEADER_LEN..(r + 1) * RECORD_LEN];
                if ItpView::new_unchecked(payload).verify_checksum() {
                    // A field the ITP checksum does not cover: undetectable
                    // without a content checksum; accepted.
                    prop_assert!(result.is_ok());
                } else {
                    match result {
                        Err(CaptureError::Damaged { stats, .. }) => prop_assert_eq!(stats.checksum_failures, 1),
                        other => prop_assert!(false, "expected Damaged, got {:?}", other.map(|c| c.stats)),
                    }
                }
            }
        }
    }

    /// A cut anywhere short of the end is refused as a cut file: inside a
    /// frame's header, block or checksum, saying where the file ends; at a
    /// block's edge, as a frame without its end mark; at 0, as empty.
    #[test]
    fn a_cut_file_is_refused(n in 1usize..30, pos in any::<prop::sample::Index>()) {
        let bytes = checksummed(&records(n, 1, 3));
        let cut = pos.index(bytes.len());
        match capture::parse(&bytes[..cut]) {
            Err(CaptureError::Cut { file_bytes, frame: 1, .. }) => prop_assert_eq!(file_bytes, cut as u64),
            Err(CaptureError::Unterminated { frame: 1, .. }) => prop_assert!(cut > 0),
            Err(CaptureError::Empty { .. }) => prop_assert_eq!(cut, 0),
            other => prop_assert!(false, "cut at {} of {}: {:?}", cut, bytes.len(), other.map(|c| c.stats)),
        }
    }
}

/// The file this crate writes round-trips and carries the content checksum.
#[test]
fn written_captures_carry_the_content_checksum() {
    let recs = records(100, 42, 9);
    let bytes = checksummed(&recs);
    // FLG byte: version 01, block independence, content checksum (bit 2).
    assert_ne!(bytes[4] & 0x04, 0, "FLG {:#04x}", bytes[4]);
    let cap = capture::parse(&bytes).unwrap();
    assert!(cap.stats.content_checksum);
    assert_eq!(cap.records, recs);
    let mut plain = Vec::new();
    lz4_flex::frame::FrameDecoder::new(&bytes[..]).read_to_end(&mut plain).unwrap();
    assert_eq!(plain, content(&recs));
}
