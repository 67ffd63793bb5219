//! The forward channel: the console's frames, off the ingress (iceoryx2,
//! UDP, memory), checked (size, flags, checksum) and released onto the
//! egress towards the robot. The stream ends on the console's end marker;
//! the robot is sent the emulator's own once every held frame is out.

use crate::frame::{ItpFrame, ItpView};
use crate::kinematics::{Kinematics, KinematicsConfig};
use crate::injector::{DropCause, Invalid};
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::service::emulator::path::ForwardChannel;
use crate::service::emulator::path::{Channel, Ending, Take};
use crate::service::link::Arrival;
use crate::service::schema::{Account, BadInput, ForwardExtra};
use crate::transport::{FrameSink, FrameSource, PortError};


/// The most frames one poll of the forward stream takes in: a burst is
/// taken whole up to this, so a fast stream pays the turn's fixed work (the
/// release check, the reverse paths' polls, the loop's own bookkeeping)
/// once per batch rather than per frame; the bound keeps those polls at
/// least every 64 decisions (about 10 µs at 150 ns a frame), and releases
/// do not wait for the batch at all: it ends as soon as one is due.
pub const TAKE_MAX: usize = 64;

/// The console → robot direction's ports and checks.
pub struct Forward<S, K> {
    /// Where frames come from.
    pub source: S,
    /// Where released frames go.
    pub sink: K,
    sample: FrameSample,
    drop_bad_checksum: bool,
    accept_raw: bool,
    bad_checksum_passed: u64,
    /// Bad input by kind.
    pub bad_input: BadInput,
    /// The motion in the frames taken in (the console's side) and released
    /// (the robot's), when followed: a frame's fields read and summed, tens
    /// of ns, taken after the release is sent.
    kinematics: Option<Box<Kinematics>>,
}

impl<S: FrameSource, K: FrameSink> Forward<S, K> {
    /// The forward channel from `source` to `sink`: frames with a wrong
    /// ITP checksum dropped when `drop_bad_checksum` (else counted and
    /// passed); opaque datagrams accepted when `accept_raw`.
    pub fn new(source: S, sink: K, drop_bad_checksum: bool, accept_raw: bool) -> Forward<S, K> {
        Forward {
            source,
            sink,
            sample: FrameSample::ZERO,
            drop_bad_checksum,
            accept_raw,
            bad_checksum_passed: 0,
            bad_input: BadInput::default(),
            kinematics: None,
        }
    }

    /// Follows the motion in the ITP frames taken in and released, when
    /// `follow`.
    pub fn following_motion(mut self, follow: bool) -> Forward<S, K> {
        self.kinematics = follow.then(|| Box::new(Kinematics::new(KinematicsConfig::default()).expect("the default settings are valid")));
        self
    }
}

/// The ITP frame a sample carries, if it is one (not an opaque datagram).
#[inline]
fn itp(s: &FrameSample) -> Option<ItpFrame> {
    (!s.is_raw() && s.len as usize == ITP_FRAME_LEN).then(|| ItpFrame::parse_unverified(&ItpView::new_unchecked(&s.wire[..])))
}

impl<S: FrameSource, K: FrameSink> ForwardChannel for Forward<S, K> {
    /// Names the senders on the ingress in the bad input seen, when there
    /// was some since the last look.
    fn name_bad_senders(&mut self, seen: &mut u64) {
        if self.bad_input.total() == *seen {
            return;
        }
        *seen = self.bad_input.total();
        for who in self.source.senders() {
            if !self.bad_input.from.contains(&who) {
                self.bad_input.from.push(who);
            }
        }
    }
}

impl<S: FrameSource, K: FrameSink> Channel for Forward<S, K> {
    type Item = FrameSample;
    type Extra = ForwardExtra;
    const NAME: &'static str = "forward";
    const TRACE_FILE: &'static str = "trace_emulator.csv";
    const ENDING: Ending = Ending::OnMarker;
    const TAKE_MAX: usize = TAKE_MAX;

    #[inline]
    fn take(&mut self, next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<FrameSample> {
        let sample = &mut self.sample;
        match self.source.try_recv(sample) {
            // An end marker is the flag alone, with no payload.
            Ok(true) if sample.flags == FrameSample::FLAG_END && sample.len == 0 => Take::End(sample.console_index),
            Ok(true) => {
                let t = clock();
                sample.ingress_index = next_ingress_index;
                sample.ingress_ns = t;
                let arrival = |sequence| Arrival { sequence, console_index: sample.console_index, send_ns: sample.send_ns };
                match classify(sample, self.drop_bad_checksum, self.accept_raw, &mut self.bad_input) {
                    Ok((seq, bad)) => {
                        self.bad_checksum_passed += u64::from(bad);
                        if let (Some(k), Some(f)) = (self.kinematics.as_deref_mut(), itp(sample)) {
                            k.console(t, &f);
                        }
                        Take::Item(*sample, None, arrival(Some(seq)))
                    }
                    Err((why, seq)) => {
                        let arrival = arrival(seq);
                        self.source.dropped(sample);
                        Take::Reject(t, why, arrival)
                    }
                }
            }
            Ok(false) => Take::Nothing,
            Err(e) => Take::Failed(e),
        }
    }

    #[inline]
    fn dropped(&mut self, item: &FrameSample, _cause: DropCause) {
        self.source.dropped(item);
    }

    /// Sends the sample stamped with its scheduled and actual release times
    /// and its injected delay.
    #[inline]
    fn release(&mut self, item: &FrameSample, scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        let sent = crate::service::emulator::path::release_stamped!(self.sink, item, scheduled_ns, stamp);
        if let (Some(k), Ok(t), Some(f)) = (self.kinematics.as_deref_mut(), &sent, itp(item)) {
            k.robot(*t, &f);
        }
        sent
    }

    fn send_end(&mut self, released: u64) {
        let _ = self.sink.send_with(&FrameSample::end_marker(released), |_| {});
    }

    fn senders(&mut self) -> Option<usize> {
        self.source.peers()
    }

    fn receivers(&mut self) -> Option<usize> {
        self.sink.peers()
    }

    fn unsubscribed(&self) -> u64 {
        self.sink.unsubscribed()
    }

    fn finish(&mut self, _account: &Account, sent: Option<u64>) -> (ForwardExtra, bool) {
        let extra = ForwardExtra {
            sent_by_console: sent,
            bad_checksum_passed: self.bad_checksum_passed,
            bad_input: std::mem::take(&mut self.bad_input),
            kinematics: self.kinematics.as_ref().map(|k| k.report()),
        };
        (extra, true)
    }
}

/// The datagram classifier: checks size and checksum. `Ok((sequence,
/// checksum_bad))` for a frame to decide; `Err` for one to reject, with
/// its sequence if readable. Total over any sample (property-tested in
/// `tests/input_prop/`).
#[inline]
pub fn classify(s: &FrameSample, drop_bad_checksum: bool, accept_raw: bool, bad: &mut BadInput) -> Result<(u32, bool), (Invalid, Option<u32>)> {
    const KNOWN: u32 = FrameSample::FLAG_END | FrameSample::FLAG_RAW;
    if s.flags & !KNOWN != 0 || s.is_end() || (s.is_raw() && !accept_raw) {
        // Garbage control bits, an end marker with a payload, or an opaque
        // datagram where none may come.
        bad.bad_flags += 1;
        return Err((Invalid::BadFlags, None));
    }
    if s.is_raw() {
        // An opaque datagram: no protocol to check; its "sequence" is its console index.
        return Ok((s.console_index as u32, false));
    }
    if s.len as usize != ITP_FRAME_LEN {
        match s.len {
            0 => bad.len_zero += 1,
            n if (n as usize) < ITP_FRAME_LEN => bad.len_short += 1,
            _ => bad.len_oversize += 1,
        }
        return Err((Invalid::WrongSize, None));
    }
    let view = ItpView::new_unchecked(&s.wire[..]);
    let seq = view.sequence();
    let bad = !view.verify_checksum();
    if bad && drop_bad_checksum {
        return Err((Invalid::BadChecksum, Some(seq)));
    }
    Ok((seq, bad))
}
