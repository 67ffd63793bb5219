//! The emulator's DDS reader and writer of one ROS 2 topic, for messages
//! of any type: a message's serialized bytes (CDR, after the 4-byte
//! encapsulation header) are copied from the DDS reader's cache straight
//! into a slot of netfi's own ([`Slots`]), never deserialized, and written
//! back out byte for byte under the same encapsulation.
//!
//! What the DDS implementation does per message is its own: RustDDS
//! allocates on receive (its cache change, its buffers) and on send (the
//! payload it keeps for resends, its cache change), and its reader takes a
//! lock on its cache. What netfi does around it allocates nothing: the
//! decoder writes into a slot fixed at start-up, the writer copies into
//! buffers it reuses once the DDS layer has let go of them ([`OutBuffers`]),
//! and the reader's cache is looked at only after the DDS layer said it
//! changed (a flag its receive thread sets), not on every turn of the loop.

use rustdds::no_key::{Decode, DeserializerAdapter, SerializerAdapter};
use rustdds::bytes::{Bytes, BytesMut};
use rustdds::{RTPSEntity, RepresentationIdentifier, Timestamp, GUID};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::task::{Wake, Waker};

/// Serialized messages held by the emulator, in slots of a fixed size
/// allocated once. A slot is taken for each message the reader hands over
/// and freed when the message is released or dropped.
pub struct Slots {
    bytes: Box<[u8]>,
    slot_bytes: usize,
    lens: Box<[u32]>,
    free: Vec<u32>,
    high_water: usize,
}

impl Slots {
    /// `slots` slots of `slot_bytes` each. The memory is reserved zeroed,
    /// so only the pages messages touch become resident.
    pub fn new(slots: usize, slot_bytes: usize) -> Slots {
        Slots {
            bytes: vec![0u8; slots * slot_bytes].into_boxed_slice(),
            slot_bytes,
            lens: vec![0u32; slots].into_boxed_slice(),
            free: (0..slots as u32).rev().collect(),
            high_water: 0,
        }
    }

    /// The largest message a slot holds, bytes.
    pub fn slot_bytes(&self) -> usize {
        self.slot_bytes
    }

    /// Slots in all.
    pub fn slots(&self) -> usize {
        self.lens.len()
    }

    /// The most slots ever in use at once.
    pub fn high_water(&self) -> usize {
        self.high_water
    }

    /// A free slot, or `None` if all are in use.
    #[inline]
    pub fn alloc(&mut self) -> Option<u32> {
        let s = self.free.pop()?;
        self.high_water = self.high_water.max(self.lens.len() - self.free.len());
        Some(s)
    }

    /// Gives `slot` back.
    #[inline]
    pub fn free(&mut self, slot: u32) {
        debug_assert!(!self.free.contains(&slot), "slot {slot} freed twice");
        self.free.push(slot);
    }

    /// The message in `slot`.
    #[inline]
    pub fn get(&self, slot: u32) -> &[u8] {
        let at = slot as usize * self.slot_bytes;
        &self.bytes[at..at + self.lens[slot as usize] as usize]
    }

    /// Puts `message` in `slot`; `false` (and nothing written) if it does
    /// not fit.
    #[inline]
    fn put(&mut self, slot: u32, message: &[u8]) -> bool {
        if message.len() > self.slot_bytes {
            return false;
        }
        let at = slot as usize * self.slot_bytes;
        self.bytes[at..at + message.len()].copy_from_slice(message);
        self.lens[slot as usize] = message.len() as u32;
        true
    }
}

/// The encapsulations the emulator relays: CDR, little endian (what every
/// ROS 2 rmw on a little-endian host writes). Its writer re-emits the same.
pub const RELAYED: RepresentationIdentifier = RepresentationIdentifier::CDR_LE;

/// What the decoder made of a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Payload {
    /// Its serialized bytes are in the slot, `len` of them.
    Stored {
        /// Bytes.
        len: u32,
    },
    /// Larger than a slot: not kept.
    TooLarge {
        /// Bytes.
        len: usize,
    },
    /// No bytes at all.
    Empty,
    /// An encapsulation the emulator does not relay (named).
    Encoding(&'static str),
}

/// The name of an encapsulation, for messages.
fn encoding_name(e: RepresentationIdentifier) -> &'static str {
    use RepresentationIdentifier as R;
    [
        (R::CDR_BE, "CDR_BE"),
        (R::CDR_LE, "CDR_LE"),
        (R::PL_CDR_BE, "PL_CDR_BE"),
        (R::PL_CDR_LE, "PL_CDR_LE"),
        (R::CDR2_BE, "CDR2_BE"),
        (R::CDR2_LE, "CDR2_LE"),
        (R::PL_CDR2_BE, "PL_CDR2_BE"),
        (R::PL_CDR2_LE, "PL_CDR2_LE"),
        (R::D_CDR_BE, "D_CDR2_BE"),
        (R::D_CDR_LE, "D_CDR2_LE"),
        (R::XML, "XML"),
    ]
    .into_iter()
    .find_map(|(r, n)| (r == e).then_some(n))
    .unwrap_or("unknown")
}

/// Every encapsulation is handed to the decoder, which keeps what it relays
/// and names the rest: a message the emulator cannot relay is a counted
/// drop with its reason, not one the DDS layer discards unseen.
const EVERY_ENCODING: &[RepresentationIdentifier] = &[
    RepresentationIdentifier::CDR_BE,
    RepresentationIdentifier::CDR_LE,
    RepresentationIdentifier::PL_CDR_BE,
    RepresentationIdentifier::PL_CDR_LE,
    RepresentationIdentifier::CDR2_BE,
    RepresentationIdentifier::CDR2_LE,
    RepresentationIdentifier::PL_CDR2_BE,
    RepresentationIdentifier::PL_CDR2_LE,
    RepresentationIdentifier::D_CDR_BE,
    RepresentationIdentifier::D_CDR_LE,
    RepresentationIdentifier::XML,
];

/// The decoder never fails: what it cannot keep, it says in its
/// [`Payload`].
type Never = std::convert::Infallible;

/// The reader's adapter: messages as [`Payload`]s.
pub struct RawCdr;

impl DeserializerAdapter<Payload> for RawCdr {
    type Error = Never;
    type Decoded = Payload;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        EVERY_ENCODING
    }

    fn transform_decoded(decoded: Payload) -> Payload {
        decoded
    }
}

/// Copies a message into one slot.
#[derive(Clone)]
struct IntoSlot<'a> {
    slots: &'a RefCell<Slots>,
    slot: u32,
}

impl<'de> Decode<'de, Payload> for IntoSlot<'_> {
    type Error = Never;

    fn decode_bytes(self, input: &'de [u8], encoding: RepresentationIdentifier) -> Result<Payload, Never> {
        if encoding != RELAYED {
            return Ok(Payload::Encoding(encoding_name(encoding)));
        }
        if input.is_empty() {
            return Ok(Payload::Empty);
        }
        if !self.slots.borrow_mut().put(self.slot, input) {
            return Ok(Payload::TooLarge { len: input.len() });
        }
        Ok(Payload::Stored { len: input.len() as u32 })
    }
}

/// The writer's adapter: a message's serialized bytes, as they are.
pub struct RawOut;

impl SerializerAdapter<Bytes> for RawOut {
    type Error = Never;

    fn output_encoding() -> RepresentationIdentifier {
        RELAYED
    }

    fn to_bytes(value: &Bytes) -> Result<Bytes, Never> {
        // A reference count, not a copy.
        Ok(value.clone())
    }
}

/// A message taken off a reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Taken {
    /// What the decoder made of it.
    pub payload: Payload,
    /// The DDS writer that sent it.
    pub writer: GUID,
    /// Its number in that writer's sequence (from 1).
    pub sequence: i64,
    /// When the writer wrote it, by its clock (the ROS 2 message info's
    /// source timestamp).
    pub source: Option<Timestamp>,
}

/// Nanoseconds since the Unix epoch of a DDS timestamp.
pub fn unix_ns(t: Timestamp) -> u64 {
    let ticks = t.to_ticks();
    (ticks >> 32) * 1_000_000_000 + (((ticks & 0xffff_ffff) * 1_000_000_000) >> 32)
}

/// A reader could not be read.
#[derive(Debug, thiserror::Error)]
#[error("reading {topic}: {source}")]
pub struct TakeError {
    /// The ROS 2 topic.
    pub topic: String,
    /// What the DDS implementation said.
    #[source]
    pub source: rustdds::dds::ReadError,
}

/// Set by the DDS layer's receive thread when a reader's cache changed.
struct Changed(AtomicBool);

impl Wake for Changed {
    fn wake(self: Arc<Self>) {
        self.0.store(true, Ordering::Release);
    }

    fn wake_by_ref(self: &Arc<Self>) {
        self.0.store(true, Ordering::Release);
    }
}

/// The emulator's reader of one topic.
///
/// The DDS layer's receive thread puts a message in the reader's cache
/// under a lock and then wakes the reader's waker, once (it takes it). A
/// loop that took the lock on every turn to find the cache empty would
/// contend with that thread on every message; this reader looks at one
/// flag instead, and takes the lock only from the flag's setting until the
/// cache is empty again, setting the waker anew before it looks (a message
/// that comes after the look then sets the flag).
pub struct Reader {
    inner: rustdds::no_key::SimpleDataReader<Payload, RawCdr>,
    topic: String,
    changed: Arc<Changed>,
    waker: Waker,
    /// The cache may hold a message not yet taken.
    looking: bool,
}

impl Reader {
    pub(super) fn new(inner: rustdds::no_key::SimpleDataReader<Payload, RawCdr>, topic: String) -> Reader {
        // Set: what came before the waker was first set is looked for.
        let changed = Arc::new(Changed(AtomicBool::new(true)));
        Reader { inner, topic, waker: Waker::from(changed.clone()), changed, looking: false }
    }

    /// Takes the next message, if one waits, into `slot` of `slots`.
    #[inline]
    pub fn take(&mut self, slots: &RefCell<Slots>, slot: u32) -> Result<Option<Taken>, TakeError> {
        if !self.looking {
            if !self.changed.0.load(Ordering::Acquire) {
                return Ok(None);
            }
            self.changed.0.store(false, Ordering::Relaxed);
            // Before the look: a message put in after it wakes this waker.
            self.inner.set_waker(Some(self.waker.clone()));
            self.looking = true;
        }
        match self.inner.try_take_one_with(IntoSlot { slots, slot }) {
            Ok(Some(c)) => Ok(Some(Taken {
                payload: c.sample,
                writer: c.writer_guid,
                sequence: i64::from(c.sequence_number),
                source: c.write_options.source_timestamp(),
            })),
            Ok(None) => {
                self.looking = false;
                Ok(None)
            }
            Err(source) => Err(TakeError { topic: self.topic.clone(), source }),
        }
    }

    /// Empties the reader's wake-up channel and has the next take look at
    /// the cache whatever the flag says (off the hot path, every few
    /// thousand turns: a change the DDS layer did not wake for, such as a
    /// reliable gap filled, is found then).
    pub fn drain_notifications(&mut self) {
        self.inner.drain_read_notifications();
        self.looking = true;
    }

    /// The reader's GUID.
    pub fn guid(&self) -> GUID {
        self.inner.guid()
    }
}

/// A write that did not go out.
#[derive(Debug, thiserror::Error)]
pub enum WriteFailure {
    /// A reliable subscriber has not acknowledged enough of what was sent:
    /// the send window is full and the emulator does not wait.
    #[error("{topic}: the reliable send window is full (a subscriber is not keeping up)")]
    WindowFull {
        /// The ROS 2 topic.
        topic: String,
    },
    /// Anything else the DDS layer reported.
    #[error("{topic}: {reason}")]
    Dds {
        /// The ROS 2 topic.
        topic: String,
        /// What the DDS implementation said.
        reason: String,
    },
}

/// The buffers the writer copies messages into: a ring of arenas, each a
/// [`BytesMut`] a message is appended to and split off as [`Bytes`] for the
/// DDS layer, which keeps it until it may no longer have to resend it. An
/// arena is reused once every message split off it has been let go of; a
/// new one is allocated only while the DDS layer holds on to more than the
/// arenas so far (its history), so in steady state nothing is allocated.
pub struct OutBuffers {
    ring: Vec<BytesMut>,
    at: usize,
}

impl Default for OutBuffers {
    fn default() -> OutBuffers {
        OutBuffers::new()
    }
}

impl OutBuffers {
    /// Arenas of at least this many bytes.
    pub const ARENA_BYTES: usize = 64 * 1024;

    /// Two arenas of [`ARENA_BYTES`](Self::ARENA_BYTES); a message larger
    /// than an arena gets one of its own size, kept for the next.
    pub fn new() -> OutBuffers {
        OutBuffers { ring: (0..2).map(|_| BytesMut::with_capacity(Self::ARENA_BYTES)).collect(), at: 0 }
    }

    /// `message`, copied into an arena.
    #[inline]
    pub fn copy(&mut self, message: &[u8]) -> Bytes {
        let n = message.len();
        for _ in 0..self.ring.len() {
            let a = &mut self.ring[self.at];
            // Room at its end, or every message split off it let go of.
            if a.try_reclaim(n) {
                a.extend_from_slice(message);
                return a.split().freeze();
            }
            self.at = (self.at + 1) % self.ring.len();
        }
        // After the newest, before the oldest: the ring stays in the order
        // its arenas were filled, which is the order they come free.
        let mut a = BytesMut::with_capacity(Self::ARENA_BYTES.max(n));
        a.extend_from_slice(message);
        let b = a.split().freeze();
        self.at += 1;
        self.ring.insert(self.at, a);
        b
    }

    /// Arenas in the ring.
    pub fn arenas(&self) -> usize {
        self.ring.len()
    }
}

/// The emulator's writer of one topic.
pub struct Writer {
    inner: rustdds::no_key::DataWriter<Bytes, RawOut>,
    topic: String,
    buffers: OutBuffers,
}

impl Writer {
    pub(super) fn new(inner: rustdds::no_key::DataWriter<Bytes, RawOut>, topic: String) -> Writer {
        Writer { inner, topic, buffers: OutBuffers::new() }
    }

    /// Writes `message` (serialized, without its encapsulation header),
    /// stamped with `source` (the original writer's time, so that the
    /// receiver's message info says when the message was first sent).
    #[inline]
    pub fn write(&mut self, message: &[u8], source: Option<Timestamp>) -> Result<(), WriteFailure> {
        let bytes = self.buffers.copy(message);
        match self.inner.write(bytes, source) {
            Ok(()) => Ok(()),
            Err(rustdds::dds::WriteError::WouldBlock { .. }) => Err(WriteFailure::WindowFull { topic: self.topic.clone() }),
            Err(e) => Err(WriteFailure::Dds { topic: self.topic.clone(), reason: e.to_string() }),
        }
    }

    /// The writer's GUID.
    pub fn guid(&self) -> GUID {
        self.inner.guid()
    }

    /// The arenas its messages were copied into.
    pub fn arenas(&self) -> usize {
        self.buffers.arenas()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_keep_messages_apart_and_refuse_what_does_not_fit() {
        let slots = RefCell::new(Slots::new(3, 8));
        let a = slots.borrow_mut().alloc().unwrap();
        let b = slots.borrow_mut().alloc().unwrap();
        let dec = |slot, bytes: &[u8], e| IntoSlot { slots: &slots, slot }.decode_bytes(bytes, e).unwrap();
        assert_eq!(dec(a, b"abc", RELAYED), Payload::Stored { len: 3 });
        assert_eq!(dec(b, b"12345678", RELAYED), Payload::Stored { len: 8 });
        assert_eq!(dec(b, b"123456789", RELAYED), Payload::TooLarge { len: 9 });
        assert_eq!(dec(b, b"", RELAYED), Payload::Empty);
        assert_eq!(dec(b, b"x", RepresentationIdentifier::CDR_BE), Payload::Encoding("CDR_BE"));
        assert_eq!(slots.borrow().get(a), b"abc");
        assert_eq!(slots.borrow().get(b), b"12345678", "a refused message leaves the slot as it was");
        assert_eq!(slots.borrow().high_water(), 2);
        slots.borrow_mut().free(a);
        let c = slots.borrow_mut().alloc().unwrap();
        let d = slots.borrow_mut().alloc().unwrap();
        assert!(slots.borrow_mut().alloc().is_none());
        assert_eq!([a, c].len() + [d].len(), 3);
    }

    #[test]
    fn timestamps_convert_to_unix_nanoseconds() {
        let t = Timestamp::from_ticks((1_700_000_000u64 << 32) | (1u64 << 31));
        assert_eq!(unix_ns(t), 1_700_000_000_500_000_000);
    }
}
