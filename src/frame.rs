//! ITP master-to-slave frame codec (docs/spec.md §2).
//!
//! Two layers, as in a network stack's wire module:
//!
//! - [`ItpView`] is a checked view over a byte buffer: construction verifies
//!   the length once, after which every field getter (and, for a mutable
//!   buffer, setter) reads or writes its bytes in place and cannot fail.
//! - [`ItpFrame`] is the validated representation with typed fields.
//!   [`ItpFrame::parse`] reads a view and verifies the checksum;
//!   [`ItpFrame::emit`] writes every field back into a view.
//!
//! The frame is 124 bytes, packed, little-endian. Byte offsets live in the
//! private `field` module and nowhere else. Nothing here allocates: a frame is
//! a plain `Copy` value and a view borrows the caller's buffer, so the codec
//! can sit on the per-frame hot path of the emulator and the simulator.
//!
//! Arrays indexed by arm hold arm 0 then arm 1, as on the wire.

/// Length of an ITP master-to-slave frame on the wire, in bytes.
pub const ITP_FRAME_LEN: usize = 124;

/// Length of an ITP frame on the wire, in bytes (the same as
/// [`ITP_FRAME_LEN`], under the codec's own name).
pub const FRAME_LEN: usize = ITP_FRAME_LEN;

/// Number of arms an ITP frame commands.
pub const ARMS: usize = 2;

/// `surgeon_mode` value meaning the clutch (foot pedal) is engaged and the
/// frame's increments apply.
pub const SURGEON_ENGAGED: i32 = 1;

/// `surgeon_mode` value meaning the clutch is released: the robot holds still.
pub const SURGEON_DISENGAGED: i32 = 0;

mod field {
    //! Byte ranges of every field (docs/spec.md §2). Arrays of two are arm 0 then arm 1.

    pub type Field = core::ops::Range<usize>;

    pub const SEQUENCE: Field = 0..4;
    pub const PACTYP: Field = 4..8;
    pub const VERSION: Field = 8..12;
    pub const DELX: Field = 12..20;
    pub const DELY: Field = 20..28;
    pub const DELZ: Field = 28..36;
    pub const QX: Field = 36..52;
    pub const QY: Field = 52..68;
    pub const QZ: Field = 68..84;
    pub const QW: Field = 84..100;
    pub const BUTTONSTATE: Field = 100..108;
    pub const GRASP: Field = 108..116;
    pub const SURGEON_MODE: Field = 116..120;
    pub const CHECKSUM: Field = 120..124;

    /// One past the last byte of the frame.
    pub const END: usize = CHECKSUM.end;
}

const _: () = assert!(field::END == FRAME_LEN);

/// Why bytes are not a valid ITP frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The buffer is not exactly one frame long. ITP frames have a fixed size,
    /// so a shorter buffer is truncated and a longer one is something else.
    #[error("wrong ITP frame length: expected {expected} bytes, got {found}")]
    WrongLength {
        /// Always [`FRAME_LEN`] (124).
        expected: usize,
        /// Length of the buffer that was offered.
        found: usize,
    },
    /// The `checksum` field disagrees with the sum docs/spec.md §2 defines over the
    /// other fields: the frame was corrupted or built without sealing it.
    #[error("ITP checksum mismatch: computed {expected} from the fields, frame carries {found}")]
    ChecksumMismatch {
        /// The checksum computed from the frame's fields.
        expected: i32,
        /// The checksum the frame carries.
        found: i32,
    },
}

/// The checksum rule of docs/spec.md §2: the wrapping 32-bit sum of `surgeon_mode`,
/// both arms' position increments, both `buttonstate`s and `sequence` (as
/// `i32`). `grasp`, the rotations, `pactyp` and `version` are not included.
#[inline]
pub fn checksum(
    sequence: u32,
    delx: [i32; ARMS],
    dely: [i32; ARMS],
    delz: [i32; ARMS],
    buttonstate: [i32; ARMS],
    surgeon_mode: i32,
) -> i32 {
    surgeon_mode
        .wrapping_add(delx[0])
        .wrapping_add(dely[0])
        .wrapping_add(delz[0])
        .wrapping_add(delx[1])
        .wrapping_add(dely[1])
        .wrapping_add(delz[1])
        .wrapping_add(buttonstate[0])
        .wrapping_add(buttonstate[1])
        .wrapping_add(sequence as i32)
}

/// A field's type as the wire carries it: little-endian, per-arm arrays
/// arm 0 then arm 1.
trait Wire: Sized {
    fn read(b: &[u8]) -> Self;
    fn write(self, b: &mut [u8]);
}

macro_rules! wire_scalar {
    ($($t:ty),*) => {$(
        impl Wire for $t {
            #[inline]
            fn read(b: &[u8]) -> $t {
                let mut bytes = [0u8; size_of::<$t>()];
                bytes.copy_from_slice(&b[..size_of::<$t>()]);
                <$t>::from_le_bytes(bytes)
            }
            #[inline]
            fn write(self, b: &mut [u8]) {
                b[..size_of::<$t>()].copy_from_slice(&self.to_le_bytes());
            }
        }

        impl Wire for [$t; ARMS] {
            #[inline]
            fn read(b: &[u8]) -> [$t; ARMS] {
                let w = size_of::<$t>();
                [<$t>::read(&b[..w]), <$t>::read(&b[w..2 * w])]
            }
            #[inline]
            fn write(self, b: &mut [u8]) {
                let w = size_of::<$t>();
                self[0].write(&mut b[..w]);
                self[1].write(&mut b[w..2 * w]);
            }
        }
    )*};
}
wire_scalar!(u32, i32, f64);

/// Bytes of the frame the checksum covers (docs/spec.md §2): `sequence`, the
/// six position increments, both `buttonstate`s, `surgeon_mode`, and the
/// `checksum` field itself: 4 + 24 + 8 + 4 + 4 = 44 of the 124.
pub const CHECKSUM_COVERED_BYTES: usize = 44;

/// Whether a change to byte `byte` of a frame changes what the checksum
/// check compares. `pactyp`, `version`, the rotations (`Qx` … `Qw`) and
/// `grasp` are not covered: a change there passes the check.
pub const fn checksum_covers(byte: usize) -> bool {
    matches!(byte, 0..=3 | 12..=35 | 100..=107 | 116..=123)
}

/// Flips bit `bit % 8` (least significant first) of byte `bit / 8` of
/// `bytes` for each index in `bits` (a [`crate::model::Verdict::Corrupt`]'s
/// bit); flipping a bit twice restores it. Indices past the buffer are
/// ignored.
#[inline]
pub fn flip_bits(bytes: &mut [u8], bits: &[u16]) {
    for &bit in bits {
        if let Some(b) = bytes.get_mut(usize::from(bit / 8)) {
            *b ^= 1 << (bit % 8);
        }
    }
}

/// Whether the ITP checksum check catches the flips `bits` applied to the
/// frame `bytes`: the flipped frame's carried checksum no longer matches its
/// fields while the original's did. One flip is caught exactly when
/// [`checksum_covers`] its byte (a single bit changes the wrapping sum by
/// ±2^k, never by 0); several flips can cancel.
pub fn checksum_catches(bytes: &[u8; FRAME_LEN], bits: &[u16]) -> bool {
    let before = ItpView::new_unchecked(&bytes[..]).verify_checksum();
    let mut flipped = *bytes;
    flip_bits(&mut flipped, bits);
    before && !ItpView::new_unchecked(&flipped[..]).verify_checksum()
}

/// A checked view of one ITP frame in a byte buffer.
///
/// Once constructed with [`ItpView::new_checked`] the buffer is known to be
/// exactly [`FRAME_LEN`] bytes, so the accessors index without failing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ItpView<T: AsRef<[u8]>> {
    buffer: T,
}

/// Each field of the frame: `getter / setter: type = byte range`, with its
/// doc; the getters read the view, the setters write it.
macro_rules! fields {
    ($($(#[doc = $doc:literal])* $get:ident / $set:ident: $t:ty = $field:ident;)*) => {
        impl<T: AsRef<[u8]>> ItpView<T> {
            $(
                $(#[doc = $doc])*
                #[inline]
                pub fn $get(&self) -> $t {
                    <$t as Wire>::read(self.bytes(field::$field))
                }
            )*
        }

        impl<T: AsRef<[u8]> + AsMut<[u8]>> ItpView<T> {
            $(
                #[doc = concat!("Sets [`ItpView::", stringify!($get), "`] as given ([`ItpView::fill_checksum`] makes the checksum agree).")]
                #[inline]
                pub fn $set(&mut self, value: $t) {
                    value.write(self.bytes_mut(field::$field));
                }
            )*
        }
    };
}

fields! {
    /// Console servo counter.
    sequence / set_sequence: u32 = SEQUENCE;
    /// Packet type.
    pactyp / set_pactyp: u32 = PACTYP;
    /// Protocol version.
    version / set_version: u32 = VERSION;
    /// Position increment along x, per arm.
    delx / set_delx: [i32; ARMS] = DELX;
    /// Position increment along y, per arm.
    dely / set_dely: [i32; ARMS] = DELY;
    /// Position increment along z, per arm.
    delz / set_delz: [i32; ARMS] = DELZ;
    /// Rotation increment, x component, per arm.
    qx / set_qx: [f64; ARMS] = QX;
    /// Rotation increment, y component, per arm.
    qy / set_qy: [f64; ARMS] = QY;
    /// Rotation increment, z component, per arm.
    qz / set_qz: [f64; ARMS] = QZ;
    /// Rotation increment, w component, per arm.
    qw / set_qw: [f64; ARMS] = QW;
    /// Button state per arm.
    buttonstate / set_buttonstate: [i32; ARMS] = BUTTONSTATE;
    /// Absolute grasper command per arm.
    grasp / set_grasp: [i32; ARMS] = GRASP;
    /// Clutch state: [`SURGEON_ENGAGED`] or [`SURGEON_DISENGAGED`].
    surgeon_mode / set_surgeon_mode: i32 = SURGEON_MODE;
    /// The checksum the frame carries.
    checksum / set_checksum: i32 = CHECKSUM;
}

impl<T: AsRef<[u8]>> ItpView<T> {
    /// Wraps a buffer without checking its length. Accessors panic if it is
    /// shorter than a frame; prefer [`ItpView::new_checked`] for untrusted
    /// input.
    pub const fn new_unchecked(buffer: T) -> ItpView<T> {
        ItpView { buffer }
    }

    /// Wraps a buffer after checking that it is exactly one frame long.
    pub fn new_checked(buffer: T) -> Result<ItpView<T>, FrameError> {
        let view = ItpView::new_unchecked(buffer);
        view.check_len()?;
        Ok(view)
    }

    /// Checks that the buffer is exactly [`FRAME_LEN`] bytes.
    pub fn check_len(&self) -> Result<(), FrameError> {
        let found = self.buffer.as_ref().len();
        if found == FRAME_LEN {
            Ok(())
        } else {
            Err(FrameError::WrongLength { expected: FRAME_LEN, found })
        }
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    #[inline]
    fn bytes(&self, f: field::Field) -> &[u8] {
        &self.buffer.as_ref()[f]
    }

    /// The checksum computed from the frame's fields.
    #[inline]
    pub fn computed_checksum(&self) -> i32 {
        checksum(
            self.sequence(),
            self.delx(),
            self.dely(),
            self.delz(),
            self.buttonstate(),
            self.surgeon_mode(),
        )
    }

    /// Whether the carried checksum matches the fields.
    #[inline]
    pub fn verify_checksum(&self) -> bool {
        self.checksum() == self.computed_checksum()
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> ItpView<T> {
    #[inline]
    fn bytes_mut(&mut self, f: field::Field) -> &mut [u8] {
        &mut self.buffer.as_mut()[f]
    }

    /// Computes the checksum from the fields and stores it.
    #[inline]
    pub fn fill_checksum(&mut self) {
        let value = self.computed_checksum();
        self.set_checksum(value);
    }
}

/// A decoded ITP frame: every wire field, typed. Per-arm arrays are arm 0
/// then arm 1.
///
/// Position increments are integers in the console's position unit (see
/// [`crate::kinematics`] for the unit the shipped capture implies); the
/// rotation fields are carried as the console wrote them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ItpFrame {
    /// Console servo counter.
    pub sequence: u32,
    /// Packet type (0 in the shipped capture).
    pub pactyp: u32,
    /// Protocol version (0 in the shipped capture).
    pub version: u32,
    /// Position increment along x.
    pub delx: [i32; ARMS],
    /// Position increment along y.
    pub dely: [i32; ARMS],
    /// Position increment along z.
    pub delz: [i32; ARMS],
    /// Rotation increment, x component.
    pub qx: [f64; ARMS],
    /// Rotation increment, y component.
    pub qy: [f64; ARMS],
    /// Rotation increment, z component.
    pub qz: [f64; ARMS],
    /// Rotation increment, w component (1.0 in the shipped capture).
    pub qw: [f64; ARMS],
    /// Button state per arm.
    pub buttonstate: [i32; ARMS],
    /// Absolute grasper command per arm.
    pub grasp: [i32; ARMS],
    /// Clutch: [`SURGEON_ENGAGED`] (increments apply) or [`SURGEON_DISENGAGED`].
    pub surgeon_mode: i32,
    /// The checksum the frame carries; see [`ItpFrame::checksum`] for the one
    /// its fields imply.
    pub checksum: i32,
}

impl ItpFrame {
    /// Reads every field of a checked view and verifies the checksum.
    pub fn parse<T: AsRef<[u8]>>(view: &ItpView<T>) -> Result<ItpFrame, FrameError> {
        let frame = ItpFrame::parse_unverified(view);
        frame.verify()?;
        Ok(frame)
    }

    /// Reads every field of a checked view without judging the checksum, for
    /// receivers that count mismatches and decide themselves what to do.
    pub fn parse_unverified<T: AsRef<[u8]>>(view: &ItpView<T>) -> ItpFrame {
        ItpFrame {
            sequence: view.sequence(),
            pactyp: view.pactyp(),
            version: view.version(),
            delx: view.delx(),
            dely: view.dely(),
            delz: view.delz(),
            qx: view.qx(),
            qy: view.qy(),
            qz: view.qz(),
            qw: view.qw(),
            buttonstate: view.buttonstate(),
            grasp: view.grasp(),
            surgeon_mode: view.surgeon_mode(),
            checksum: view.checksum(),
        }
    }

    /// Checks the length of `bytes` and parses them, verifying the checksum.
    pub fn from_bytes(bytes: &[u8]) -> Result<ItpFrame, FrameError> {
        ItpFrame::parse(&ItpView::new_checked(bytes)?)
    }

    /// Writes every field, the carried `checksum` included, into a view.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, view: &mut ItpView<T>) {
        view.set_sequence(self.sequence);
        view.set_pactyp(self.pactyp);
        view.set_version(self.version);
        view.set_delx(self.delx);
        view.set_dely(self.dely);
        view.set_delz(self.delz);
        view.set_qx(self.qx);
        view.set_qy(self.qy);
        view.set_qz(self.qz);
        view.set_qw(self.qw);
        view.set_buttonstate(self.buttonstate);
        view.set_grasp(self.grasp);
        view.set_surgeon_mode(self.surgeon_mode);
        view.set_checksum(self.checksum);
    }

    /// The frame's wire bytes.
    pub fn to_bytes(&self) -> [u8; FRAME_LEN] {
        let mut bytes = [0u8; FRAME_LEN];
        self.emit(&mut ItpView::new_unchecked(&mut bytes[..]));
        bytes
    }

    /// The checksum docs/spec.md §2 defines over this frame's fields (not the carried
    /// `checksum` field).
    #[inline]
    pub fn checksum(&self) -> i32 {
        checksum(self.sequence, self.delx, self.dely, self.delz, self.buttonstate, self.surgeon_mode)
    }

    /// Whether the carried `checksum` matches the fields.
    #[inline]
    pub fn has_valid_checksum(&self) -> bool {
        self.checksum == self.checksum()
    }

    /// Fails with [`FrameError::ChecksumMismatch`] if the carried checksum
    /// does not match the fields.
    pub fn verify(&self) -> Result<(), FrameError> {
        let expected = self.checksum();
        if self.checksum == expected {
            Ok(())
        } else {
            Err(FrameError::ChecksumMismatch { expected, found: self.checksum })
        }
    }

    /// Fills in the checksum from the current fields.
    #[inline]
    pub fn seal(&mut self) {
        self.checksum = self.checksum();
    }

    /// This frame with its checksum filled in.
    #[inline]
    pub fn with_checksum(mut self) -> ItpFrame {
        self.seal();
        self
    }

    /// Whether the clutch is engaged, i.e. the increments apply.
    #[inline]
    pub fn clutch_engaged(&self) -> bool {
        self.surgeon_mode == SURGEON_ENGAGED
    }

    /// Position increment `[x, y, z]` of one arm.
    #[inline]
    pub fn increment(&self, arm: usize) -> [i32; 3] {
        [self.delx[arm], self.dely[arm], self.delz[arm]]
    }

    /// Rotation increment `[x, y, z, w]` of one arm.
    #[inline]
    pub fn rotation(&self, arm: usize) -> [f64; 4] {
        [self.qx[arm], self.qy[arm], self.qz[arm], self.qw[arm]]
    }
}

#[cfg(test)]
mod tests;
