use super::*;
use crate::frame::SURGEON_DISENGAGED;
use super::reader::LZ4_MAGIC;
use crate::frame::{ItpFrame, FRAME_LEN};
use lz4_flex::frame::{FrameDecoder, FrameEncoder};
use std::io::Write;

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

/// A capture is read up to its limit of records: exactly the limit is
/// read, one more is refused when it begins; what is kept never outgrows
/// the limit (a repeated record packs millions into a small file).
#[test]
fn records_beyond_the_limit_are_refused_and_never_kept() {
    let r = CaptureRecord::new(1_000, &frame(1, 1));
    for n in [1usize, 999, 1000, 1001, 2500] {
        let bytes = capture_bytes(&vec![r; n]);
        let limits = CaptureLimits::records(1000);
        match parse_with(&bytes, limits) {
            Ok(cap) => {
                assert!(n <= 1000, "{n} records read under a limit of 1000");
                assert_eq!(cap.records.len(), n);
                assert!(cap.records.capacity() <= 1000, "{n}: capacity {}", cap.records.capacity());
            }
            Err(CaptureError::TooManyRecords { max_records: 1000, path: None }) => assert!(n > 1000, "{n} refused"),
            Err(e) => panic!("{n}: {e}"),
        }
        // The same limit for a reader whose records are not kept.
        let mut seen = 0u64;
        let scanned = scan(CaptureReader::new(&bytes[..]), limits, |_| seen += 1);
        assert_eq!(scanned.is_ok(), n <= 1000, "{n}");
        assert_eq!(seen, n.min(1000) as u64);
    }
    let e = parse_with(&capture_bytes(&[r; 3]), CaptureLimits::records(2)).unwrap_err().to_string();
    assert_eq!(
        e,
        "capture stream: more than 2 records, the most it is read with (default 4194304): --capture-max-records, or a replay stage's `max_records`, raises the limit"
    );
    assert_eq!(CaptureLimits::default().max_records, 1 << 22);
    assert_eq!(CaptureLimits::records(2).max_content_bytes(), 2 * 138 + 14);
}

/// A file cut inside an LZ4 frame (its header, a block, the checksum) says
/// it was cut and where in the file, not a decompressed offset.
#[test]
fn a_file_cut_inside_a_block_says_where_the_file_ends() {
    let (_, bytes) = batched(300, 300);
    for cut in [3, 6, bytes.len() / 2, bytes.len() - 2] {
        match parse(&bytes[..cut]) {
            Err(CaptureError::Cut { file_bytes, frame: 1, .. }) => assert_eq!(file_bytes, cut as u64),
            other => panic!("cut at {cut} of {}: {:?}", bytes.len(), other.map(|c| c.stats)),
        }
    }
    let e = parse(&bytes[..bytes.len() / 2]).unwrap_err().to_string();
    assert!(e.starts_with(&format!("capture stream: the file was cut short: it ends at byte {} of the file, inside LZ4 frame 1", bytes.len() / 2)), "{e}");
    assert!(!e.contains("fill whole buffer"), "{e}");
}

/// Without a content checksum, the record header's time and flag or
/// delay, and the frame bytes the ITP checksum leaves out, are named as
/// unverified; the names cover exactly the bytes no checksum covers.
#[test]
fn what_no_checksum_covers_is_named() {
    let uncovered: Vec<usize> = (0..FRAME_LEN).filter(|&b| !crate::frame::checksum_covers(b)).collect();
    let named: Vec<usize> = FRAME_FIELDS_UNCHECKED.iter().flat_map(|(_, r)| r.clone()).collect();
    assert_eq!(named, uncovered);
    let r = CaptureRecord::new(5, &frame(1, 1));
    let with = parse(&capture_bytes(&[r; 3])).unwrap().note();
    assert!(with.content_checksum && with.unverified.is_empty() && with.unverified_warning().is_none(), "{with:?}");
    let mut content = Vec::new();
    for _ in 0..3 {
        content.extend_from_slice(&5u64.to_be_bytes());
        content.extend_from_slice(&124u16.to_be_bytes());
        content.push(0);
        content.extend_from_slice(&r.payload);
    }
    let without = parse(&lz4(&content)).unwrap().note();
    assert!(!without.content_checksum);
    assert_eq!(without.unverified, ["time_ns", "dropped", "frame.pactyp", "frame.version", "frame.Qx", "frame.Qy", "frame.Qz", "frame.Qw", "frame.grasp"]);
    let w = without.unverified_warning().unwrap();
    assert!(w.contains("no LZ4 content checksum") && w.contains("time_ns and dropped") && w.contains("(pactyp, version, Qx, Qy, Qz, Qw, grasp)"), "{w}");
    assert_eq!(unverified_fields(RecordLayout::Delay)[..2], ["time_ns", "delay_s"]);
    let json = serde_json::to_value(&without).unwrap();
    assert_eq!(json["layout"], "dropped");
    assert_eq!(serde_json::from_value::<CaptureNote>(json).unwrap(), without);
}

/// A FIFO given as a capture is refused at once, not waited on.
#[test]
fn a_fifo_is_refused_without_waiting_for_a_writer() {
    let dir = crate::scratch::dir("capture-fifo");
    let fifo = dir.join("fifo.bin");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let e = load(&fifo).unwrap_err().to_string();
    assert!(e.contains("fifo.bin") && e.contains("a FIFO: only regular files are read"), "{e}");
    assert!(load("/dev/null").unwrap_err().to_string().contains("a device"));
    std::fs::remove_dir_all(&dir).unwrap();
}
