use super::*;

/// A frame whose every field has a distinct value.
fn sample_frame() -> ItpFrame {
    ItpFrame {
        sequence: 20468,
        pactyp: 7,
        version: 3,
        delx: [-39, 13],
        dely: [19, -44],
        delz: [34, -10],
        qx: [0.25, -1.0],
        qy: [2.0, 0.5],
        qz: [-0.125, 1.5],
        qw: [1.0, 0.75],
        buttonstate: [2597, 845],
        grasp: [120, -30],
        surgeon_mode: SURGEON_ENGAGED,
        checksum: 0,
    }
    .with_checksum()
}

#[test]
fn round_trip_through_bytes() {
    let frame = sample_frame();
    let bytes = frame.to_bytes();
    assert_eq!(ItpFrame::from_bytes(&bytes), Ok(frame));
    let mut again = [0u8; FRAME_LEN];
    ItpFrame::from_bytes(&bytes).unwrap().emit(&mut ItpView::new_unchecked(&mut again[..]));
    assert_eq!(again, bytes);
}

#[test]
fn round_trip_preserves_arbitrary_bytes() {
    // Every byte pattern is a frame (the rotations may be any f64, NaNs
    // included); parsing and re-emitting must not change a bit.
    let mut bytes = [0u8; FRAME_LEN];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = (i as u8).wrapping_mul(37).wrapping_add(11);
    }
    bytes[36..44].copy_from_slice(&f64::from_bits(0x7ff8_dead_beef_0001).to_le_bytes());
    let view = ItpView::new_checked(&bytes[..]).unwrap();
    let frame = ItpFrame::parse_unverified(&view);
    assert_eq!(frame.to_bytes(), bytes);
}

#[test]
fn every_field_at_its_offset() {
    let f = sample_frame();
    let b = f.to_bytes();
    let i32_at = |o: usize| i32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let f64_at = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    assert_eq!(u32_at(0), 20468);
    assert_eq!(u32_at(4), 7);
    assert_eq!(u32_at(8), 3);
    assert_eq!([i32_at(12), i32_at(16)], [-39, 13]);
    assert_eq!([i32_at(20), i32_at(24)], [19, -44]);
    assert_eq!([i32_at(28), i32_at(32)], [34, -10]);
    assert_eq!([f64_at(36), f64_at(44)], [0.25, -1.0]);
    assert_eq!([f64_at(52), f64_at(60)], [2.0, 0.5]);
    assert_eq!([f64_at(68), f64_at(76)], [-0.125, 1.5]);
    assert_eq!([f64_at(84), f64_at(92)], [1.0, 0.75]);
    assert_eq!([i32_at(100), i32_at(104)], [2597, 845]);
    assert_eq!([i32_at(108), i32_at(112)], [120, -30]);
    assert_eq!(i32_at(116), 1);
    assert_eq!(i32_at(120), f.checksum);
}

#[test]
fn view_reads_a_known_byte_pattern() {
    // Byte i holds i, so each little-endian field is predictable.
    let mut bytes = [0u8; FRAME_LEN];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = i as u8;
    }
    let le32 = |o: usize| u32::from_le_bytes([o as u8, o as u8 + 1, o as u8 + 2, o as u8 + 3]);
    let lef = |o: usize| f64::from_le_bytes(core::array::from_fn(|k| (o + k) as u8));
    let v = ItpView::new_checked(&bytes).unwrap();
    assert_eq!(v.sequence(), le32(0));
    assert_eq!(v.pactyp(), le32(4));
    assert_eq!(v.version(), le32(8));
    assert_eq!(v.delx(), [le32(12) as i32, le32(16) as i32]);
    assert_eq!(v.dely(), [le32(20) as i32, le32(24) as i32]);
    assert_eq!(v.delz(), [le32(28) as i32, le32(32) as i32]);
    assert_eq!(v.qx().map(f64::to_bits), [lef(36), lef(44)].map(f64::to_bits));
    assert_eq!(v.qy().map(f64::to_bits), [lef(52), lef(60)].map(f64::to_bits));
    assert_eq!(v.qz().map(f64::to_bits), [lef(68), lef(76)].map(f64::to_bits));
    assert_eq!(v.qw().map(f64::to_bits), [lef(84), lef(92)].map(f64::to_bits));
    assert_eq!(v.buttonstate(), [le32(100) as i32, le32(104) as i32]);
    assert_eq!(v.grasp(), [le32(108) as i32, le32(112) as i32]);
    assert_eq!(v.surgeon_mode(), le32(116) as i32);
    assert_eq!(v.checksum(), le32(120) as i32);
}

#[test]
fn setters_touch_only_their_bytes() {
    let mut bytes = [0xAAu8; FRAME_LEN];
    let mut v = ItpView::new_checked(&mut bytes[..]).unwrap();
    v.set_grasp([0x0102_0304, 0x0506_0708]);
    assert_eq!(&bytes[108..116], &[4, 3, 2, 1, 8, 7, 6, 5]);
    assert!(bytes[..108].iter().chain(&bytes[116..]).all(|&b| b == 0xAA));
}

#[test]
fn the_checksum_catches_exactly_the_flips_in_the_bytes_it_covers() {
    let frame = ItpFrame {
        sequence: 77,
        delx: [3, -4],
        dely: [5, 6],
        delz: [-7, 8],
        qw: [1.0, 1.0],
        buttonstate: [1, 0],
        grasp: [100, -100],
        surgeon_mode: SURGEON_ENGAGED,
        ..ItpFrame::default()
    }
    .with_checksum();
    let bytes = frame.to_bytes();
    let mut covered = 0;
    for bit in 0..(FRAME_LEN * 8) as u16 {
        let byte = usize::from(bit / 8);
        assert_eq!(checksum_catches(&bytes, &[bit]), checksum_covers(byte), "bit {bit}");
        covered += usize::from(checksum_covers(byte) && bit % 8 == 0);
    }
    assert_eq!(covered, CHECKSUM_COVERED_BYTES);
    // grasp (108..116) is not covered: a flip there passes.
    assert!(!checksum_catches(&bytes, &[108 * 8 + 3]));
    // Two flips that cancel in the sum: +2^0 in delx[0] and −2^0 in dely[0]
    // (delx[0] = 3 has bit 0 set → 2; dely[0] = 5 … use bit 1: 5 → 7, 3 → 1).
    assert!(!checksum_catches(&bytes, &[12 * 8 + 1, 20 * 8 + 1]));
    let mut twice = bytes;
    flip_bits(&mut twice, &[5, 5]);
    assert_eq!(twice, bytes);
}

#[test]
fn checksum_matches_a_capture_frame() {
    // First frame of the shipped capture: sequence 20468, no motion,
    // buttonstate [0, -30], clutch engaged, checksum 20439.
    let f = ItpFrame {
        sequence: 20468,
        qw: [1.0, 1.0],
        buttonstate: [0, -30],
        grasp: [0, -30],
        surgeon_mode: 1,
        checksum: 20439,
        ..ItpFrame::default()
    };
    assert_eq!(f.checksum(), 20439);
    assert!(f.has_valid_checksum());
}

#[test]
fn checksum_sums_the_specified_fields() {
    let f = ItpFrame {
        sequence: 1000,
        delx: [1, 10],
        dely: [2, 20],
        delz: [3, 30],
        buttonstate: [100, 200],
        surgeon_mode: 1,
        ..ItpFrame::default()
    };
    assert_eq!(f.checksum(), 1000 + 1 + 10 + 2 + 20 + 3 + 30 + 100 + 200 + 1);
}

#[test]
fn checksum_wraps_and_reads_sequence_as_i32() {
    let f = ItpFrame { sequence: u32::MAX, delx: [i32::MAX, 0], surgeon_mode: 1, ..ItpFrame::default() };
    // u32::MAX as i32 is -1; -1 + i32::MAX + 1 = i32::MAX.
    assert_eq!(f.checksum(), i32::MAX);
    let g = ItpFrame { delx: [i32::MAX, 1], ..ItpFrame::default() };
    assert_eq!(g.checksum(), i32::MIN);
}

#[test]
fn checksum_excludes_grasp_rotation_and_header() {
    let f = sample_frame();
    let g = ItpFrame {
        grasp: [9999, -9999],
        qx: [5.0, 5.0],
        qy: [6.0, 6.0],
        qz: [7.0, 7.0],
        qw: [0.0, 0.0],
        pactyp: 99,
        version: 98,
        ..f
    };
    assert_eq!(g.checksum(), f.checksum());
    assert!(g.has_valid_checksum());
}

#[test]
fn wrong_length_is_an_error() {
    assert_eq!(
        ItpView::new_checked(&[0u8; 123][..]),
        Err(FrameError::WrongLength { expected: 124, found: 123 })
    );
    assert_eq!(
        ItpFrame::from_bytes(&[0u8; 125]),
        Err(FrameError::WrongLength { expected: 124, found: 125 })
    );
    assert_eq!(
        ItpFrame::from_bytes(&[]).unwrap_err().to_string(),
        "wrong ITP frame length: expected 124 bytes, got 0"
    );
}

#[test]
fn wrong_checksum_is_an_error() {
    let mut f = sample_frame();
    let good = f.checksum;
    f.checksum = good.wrapping_add(1);
    let bytes = f.to_bytes();
    assert_eq!(
        ItpFrame::from_bytes(&bytes),
        Err(FrameError::ChecksumMismatch { expected: good, found: good + 1 })
    );
    let view = ItpView::new_checked(&bytes[..]).unwrap();
    assert!(!view.verify_checksum());
    assert_eq!(ItpFrame::parse_unverified(&view), f);
}

#[test]
fn view_fill_checksum_agrees_with_repr() {
    let mut f = sample_frame();
    f.checksum = 0;
    let mut bytes = f.to_bytes();
    let mut view = ItpView::new_checked(&mut bytes[..]).unwrap();
    view.fill_checksum();
    assert!(view.verify_checksum());
    assert_eq!(view.checksum(), f.checksum());
}
