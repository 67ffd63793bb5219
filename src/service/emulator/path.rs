//! A path: one direction of the emulator around a [`Link`], written once.
//!
//! What differs between the directions (the forward stream console →
//! robot, the robot's feedback, the camera's video, the UDP return) is a
//! [`Channel`]: the item the link holds, how one is taken off the port and
//! released onto the other, the end marker, and what the channel adds to
//! the report. Everything else lives here, once: polling (due releases,
//! then at most [`Channel::TAKE_MAX`] items in), the end ([`Ending`]: the
//! sender's end marker, a sender gone, a grace time), the trace kept off
//! the loop's core, the account and its conservation check, and the
//! report ([`PathReport`]).
//!
//! A path's poll allocates nothing, takes no lock and makes no system call
//! beyond its ports' own; the clock is the vDSO's.

use crate::clock::{now_from_ns, now_ns};
use crate::injector::{DropCause, Fate, Invalid};
use crate::scenario::Scenario;
use crate::service::link::{Arrival, Carried, Link, Release};
use crate::service::schema::{Account, PathReport};
use crate::transport::PortError;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::{Path as FsPath, PathBuf};

/// The release of a sample that carries its own stamps (ITP frames,
/// feedback): `$item` sent on `$sink` (whose `send_with` lets a closure
/// have the last word on the copy it sends) stamped with its scheduled
/// release time, its injected delay and, read by `$stamp` immediately
/// before the send, its actual release time; that time, or the time of the
/// failure and why. A macro, so that each channel's release compiles to
/// exactly the code it had when each wrote it out.
macro_rules! release_stamped {
    ($sink:expr, $item:expr, $scheduled_ns:expr, $stamp:expr) => {{
        let (scheduled_ns, stamp): (u64, _) = ($scheduled_ns, $stamp);
        let mut release_ns = 0;
        let sent = $sink.send_with($item, |s| {
            s.release_sched_ns = scheduled_ns;
            s.injected_delay_ns = scheduled_ns - s.ingress_ns;
            release_ns = stamp();
            s.release_ns = release_ns;
        });
        match sent {
            Ok(_) => Ok(release_ns),
            Err(e) => Err((crate::clock::now_ns(), e)),
        }
    }};
}
pub(crate) use release_stamped;

/// Why a path could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    /// The link refused the scenario or its queue.
    #[error(transparent)]
    Link(#[from] crate::service::link::LinkError),
    /// The trace (or a histogram log) could not be opened to stream to.
    #[error(transparent)]
    Stream(#[from] crate::durable::DurableError),
    #[error(transparent)]
    Histograms(#[from] crate::service::link::HistogramWriteError),
    /// The trace could not be written out at the end.
    #[error(transparent)]
    Trace(#[from] crate::trace::TraceError),
    /// The report as JSON.
    #[error(transparent)]
    Report(#[from] serde_json::Error),
}

/// What a channel's port gave when asked for one item.
pub enum Take<T> {
    /// An item to decide, stamped with the time it was taken in (its
    /// [`Carried::ingress_ns`]); its payload's size when the link stages
    /// should see it (variable-size payloads), and what the trace keeps.
    Item(T, Option<u64>, Arrival),
    /// Bad input, taken in at this time: it enters and is dropped for its
    /// reason.
    Reject(u64, Invalid, Arrival),
    /// The sender's end marker: the items it says it sent.
    End(u64),
    /// Something was taken that does not enter the link (counted by the
    /// channel); look again.
    Skipped,
    /// Nothing waits.
    Nothing,
    /// The port failed: counted, and the poll ends (a failing port is not
    /// spun on).
    Failed(PortError),
}

/// How a path ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// On its sender's end marker, once nothing is held: the forward stream.
    OnMarker,
    /// Once the forward stream has ended: on its sender's end marker, or
    /// with no sender left, once nothing is held; at the latest `grace_ns`
    /// after the forward stream ended (what is held then is held at the
    /// end: a queue that would take longer to drain does not hold the
    /// run). The robot's feedback and video.
    AfterForward { grace_ns: u64 },
    /// With the forward stream, whatever it holds then: a transport
    /// without an end of stream (the UDP return).
    WithForward,
}

/// The longest a path that ends after the forward stream waits, once that
/// stream has ended, for its sender's end marker and its queue: 2 s.
pub const GRACE_NS: u64 = 2_000_000_000;

/// A sender is gone when none is connected and nothing came from it for
/// this long (a sender that just left may still have items in flight).
const GONE_QUIET_NS: u64 = 50_000_000;

/// How often a lane whose reverse paths were quiet at their last poll polls
/// them again: every 4th turn. A poll of an empty iceoryx2 port costs about
/// as much as the rest of an idle turn, and the reverse paths are not the
/// command stream: while they are quiet, what comes on them waits at most
/// three turns more (well under a microsecond); once one is busy, they are
/// polled every turn again. A path may ask for more ([`Reverse::quiet_poll_every`]):
/// the UDP return, whose idle turns are a system call each, is polled every
/// turn.
pub const REVERSE_EVERY: u32 = 4;

/// What differs between the directions of the emulator.
pub trait Channel {
    /// What the link holds.
    type Item: Carried;
    /// What the channel adds to its path's report (flattened into it).
    type Extra: Serialize + DeserializeOwned;
    /// Its name in logs, in the report (the key of its section) and in
    /// its seed's derivation.
    const NAME: &'static str;
    /// Its trace file, in the run's directory.
    const TRACE_FILE: &'static str;
    /// As a reverse path, how often it is polled while the lane's reverse
    /// paths are quiet: every this many turns (see
    /// [`REVERSE_EVERY`], the default).
    const QUIET_POLL_EVERY: u32 = REVERSE_EVERY;
    /// How its path ends.
    const ENDING: Ending;
    /// The most items one poll takes in. A burst taken whole pays the
    /// poll's fixed work once; the bound keeps the loop's other work
    /// coming at least every so many decisions.
    const TAKE_MAX: usize = 1;

    /// Takes at most one item off the port. `next_ingress_index` is the
    /// index the link will give it; `clock` reads the time it is taken in
    /// (call it once, only when something came).
    fn take(&mut self, next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<Self::Item>;

    /// `item` was dropped (`cause`) and is held nowhere: free what it
    /// holds outside the link.
    #[inline]
    fn dropped(&mut self, _item: &Self::Item, _cause: DropCause) {}

    /// Sends `item`, due at `scheduled_ns`, stamped at `stamp()` as late as
    /// possible. Returns the time it went out, or that time and the error.
    fn release(&mut self, item: &Self::Item, scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)>;

    /// Sends the receiver the end marker (best effort), carrying the items
    /// released.
    fn send_end(&mut self, released: u64);

    /// Senders connected now, where the port knows. Off the hot path.
    fn senders(&mut self) -> Option<usize> {
        None
    }

    /// Receivers connected now, where the port knows. Off the hot path.
    fn receivers(&mut self) -> Option<usize> {
        None
    }

    /// Items sent while no receiver was connected, where the port knows.
    fn unsubscribed(&self) -> u64 {
        0
    }

    /// At the end: what the channel adds to the report, and whether its
    /// own counts agree with the link's `account` and the sender's word
    /// (`sent`, from its end marker).
    fn finish(&mut self, account: &Account, sent: Option<u64>) -> (Self::Extra, bool);
}

/// What a lane asks of its forward channel beyond what every channel
/// gives: its report is the forward stream's (`emulator.json`'s frames).
pub trait ForwardChannel: Channel<Extra = crate::service::schema::ForwardExtra> {
    /// Off the hot path: names who sent the bad input seen since the count
    /// `seen` (which it updates).
    fn name_bad_senders(&mut self, _seen: &mut u64) {}
}

/// One step of a poll's intake.
enum Step {
    /// An item entered, taken in at this time.
    Took(u64),
    /// Something came that did not enter (an end marker, a skipped item).
    Again,
    /// Nothing came, or the port failed.
    Stop,
}

/// A direction of the emulator: a [`Link`] between the ports of a
/// [`Channel`].
pub struct Path<C: Channel> {
    /// The link every item goes through.
    pub link: Link<C::Item>,
    /// The channel: the ports and what is particular to the direction.
    pub chan: C,
    seed: u64,
    /// Items the sender said it sent (from its end marker), once it came.
    sent: Option<u64>,
    /// When this path sent its receiver the end marker.
    end_ns: Option<u64>,
    /// Items sent to no receiver, counted just before the end marker.
    unsubscribed: u64,
    receive_errors: u64,
    last_error: Option<PortError>,
    last_take_ns: u64,
    trace_path: PathBuf,
    hlogs: bool,
    /// Closed after the loop ([`Path::close`]): nothing more goes through.
    closed: bool,
}

/// The release side of a path: its channel, stamping at the clock.
struct Out<'a, C>(&'a mut C);

impl<C: Channel> Release<C::Item> for Out<'_, C> {
    #[inline]
    fn release(&mut self, item: &C::Item, scheduled_ns: u64) -> Result<u64, (u64, PortError)> {
        self.0.release(item, scheduled_ns, now_ns)
    }
}

/// The release side of a path handed releases ahead of their time: each
/// waits on the clock for its scheduled moment, the last thing before the
/// send, so it is never sent early and is stamped within a clock read of
/// its time.
struct OnTime<'a, C>(&'a mut C);

impl<C: Channel> Release<C::Item> for OnTime<'_, C> {
    #[inline]
    fn release(&mut self, item: &C::Item, scheduled_ns: u64) -> Result<u64, (u64, PortError)> {
        self.0.release(item, scheduled_ns, || now_from_ns(scheduled_ns))
    }
}

impl<C: Channel> Path<C> {
    /// The path of `chan` through `scenario` (seeded with `seed`), holding
    /// at most `queue_capacity` items; `expected` sizes the trace and the
    /// loss interval's batches (a guess is fine). Its trace streams to
    /// `<out_dir>/<C::TRACE_FILE>` as the run goes, and with `hlogs` the
    /// decision-time and release-lateness histograms too, as interval logs
    /// in `out_dir`. Starts the trace's writer thread: build paths before
    /// pinning the loop, then keep their traces off its core.
    pub fn new(chan: C, scenario: Scenario, seed: u64, queue_capacity: usize, expected: u64, out_dir: &FsPath, hlogs: bool) -> Result<Path<C>, PathError> {
        let mut link = Link::new(scenario, queue_capacity, expected)?;
        let trace_path = out_dir.join(C::TRACE_FILE);
        link.stream_to(&trace_path, hlogs.then_some(out_dir))?;
        Ok(Path::of(link, chan, seed, trace_path, hlogs))
    }

    /// The path of `chan` around `link` as it is (tests drive links that do
    /// not stream); its trace is written to `trace_path` at the end.
    pub fn of(link: Link<C::Item>, chan: C, seed: u64, trace_path: PathBuf, hlogs: bool) -> Path<C> {
        Path { link, chan, seed, sent: None, end_ns: None, unsubscribed: 0, receive_errors: 0, last_error: None, last_take_ns: 0, trace_path, hlogs, closed: false }
    }

    /// The seed of the path's scenario.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// One poll: every due release, then what waits at the port (up to
    /// [`Channel::TAKE_MAX`]), then what of it is due already: an item with
    /// no delay goes out in the poll that took it, not a turn later behind
    /// the lane's other ports. Returns whether nothing waited.
    #[inline]
    pub fn poll(&mut self) -> bool {
        self.release_due(now_ns());
        let idle = self.take(now_ns);
        if !idle && self.link.next_release_ns().is_some_and(|due| due <= self.last_take_ns) {
            self.release_due(self.last_take_ns);
        }
        idle
    }

    /// Releases every item due at `now`, oldest first.
    #[inline]
    pub fn release_due(&mut self, now: u64) {
        self.link.release_due(now, &mut Out(&mut self.chan));
    }

    /// Releases every item due at `t`, a moment ahead: each is taken out
    /// and written now, and sent once the clock reaches its time.
    #[inline]
    pub fn release_ahead(&mut self, t: u64) {
        self.link.release_due(t, &mut OnTime(&mut self.chan));
    }

    /// Takes what waits at the port, up to [`Channel::TAKE_MAX`] items, each
    /// stamped taken in at `clock()` and decided. The intake ends early once
    /// a held item is due at the time the last one was taken, so that a
    /// release waits behind at most one decision. Returns whether nothing
    /// waited at all.
    #[inline]
    pub fn take(&mut self, mut clock: impl FnMut() -> u64) -> bool {
        for i in 0..C::TAKE_MAX {
            match self.take_one(&mut clock) {
                Step::Took(t) if self.link.next_release_ns().is_some_and(|due| due <= t) => return false,
                Step::Took(_) | Step::Again => {}
                Step::Stop => return i == 0,
            }
        }
        false
    }

    #[inline]
    fn take_one(&mut self, clock: &mut impl FnMut() -> u64) -> Step {
        match self.chan.take(self.link.next_ingress_index(), clock) {
            Take::Item(item, len, arrival) => {
                let t = item.ingress_ns();
                self.last_take_ns = t;
                let entered = self.link.ingress_len(t, item, len, arrival);
                // A copy still queued shares what the item holds.
                if let (Fate::Dropped(cause), 0) = (entered.fate, entered.copies) {
                    self.chan.dropped(&item, cause);
                }
                Step::Took(t)
            }
            Take::Reject(t, why, arrival) => {
                self.last_take_ns = t;
                self.link.reject(t, why, arrival);
                Step::Took(t)
            }
            Take::End(sent) => {
                self.sent = Some(sent);
                Step::Again
            }
            Take::Skipped => Step::Again,
            Take::Nothing => Step::Stop,
            Take::Failed(e) => {
                self.receive_errors += 1;
                self.last_error = Some(e);
                Step::Stop
            }
        }
    }

    /// Items the sender said it sent, once its end marker came.
    pub fn sent(&self) -> Option<u64> {
        self.sent
    }

    /// When this path sent its receiver the end marker, if it has.
    pub fn ended_at(&self) -> Option<u64> {
        self.end_ns
    }

    /// Off the hot path: whether the path has ended at `now`, the forward
    /// stream having ended at `forward_end_ns` (if it has), by its
    /// [`Ending`]. Sends the receiver the end marker when it ends.
    pub fn finished(&mut self, now: u64, forward_end_ns: Option<u64>) -> bool {
        if self.end_ns.is_some() {
            return true;
        }
        let held = self.link.held();
        let done = match (C::ENDING, forward_end_ns) {
            (Ending::OnMarker, _) => self.sent.is_some() && held == 0,
            (Ending::AfterForward { grace_ns }, Some(end)) => {
                let gone = self.chan.senders() == Some(0) && now.saturating_sub(self.last_take_ns) > GONE_QUIET_NS;
                (held == 0 && (self.sent.is_some() || gone)) || now.saturating_sub(end) > grace_ns
            }
            (Ending::WithForward, Some(_)) => true,
            (_, None) => false,
        };
        if done {
            self.end(now);
        }
        done
    }

    /// Sends the receiver the end marker now (once): the path's sender is
    /// gone, or the run stops.
    pub fn end(&mut self, now: u64) {
        if self.end_ns.is_none() {
            self.unsubscribed = self.chan.unsubscribed();
            self.chan.send_end(self.link.released());
            self.end_ns = Some(now);
        }
    }

    /// Keeps the trace's writer thread off `core` (the loop's); `false`
    /// where it may use no other core.
    pub fn keep_trace_off_core(&self, core: usize) -> bool {
        self.link.keep_trace_off_core(core)
    }

    /// After the loop: releases what is due, sends the end marker (unless
    /// sent), and asks the trace writer to finish writing without waiting
    /// for it, so that many paths' traces are written and synced at once
    /// (a stop with many lanes would otherwise wait for each in turn).
    /// Nothing goes through the path after; [`Path::finish`] closes it if
    /// it is not.
    pub fn close(&mut self) {
        if !self.closed {
            let now = now_ns();
            self.release_due(now);
            self.end(now);
            self.link.close_trace();
            self.closed = true;
        }
    }

    /// After the loop: closes the path ([`Path::close`]), waits for the
    /// trace writer to have written the trace (and, with hlogs, the
    /// histograms), checks that every item is accounted for, and reports.
    /// `duration_ns` is the time the path ran.
    pub fn finish(mut self, duration_ns: u64) -> Result<PathReport<C::Extra>, PathError> {
        self.close();
        let hlogs = match self.hlogs {
            true => {
                let dir = self.trace_path.parent().unwrap_or(FsPath::new("."));
                Some(self.link.write_histograms(dir, duration_ns as f64 / 1e9)?)
            }
            false => None,
        };
        let l = self.link.finish(&self.trace_path, duration_ns)?;
        if let Some(e) = &self.last_error {
            eprintln!("emulator: {}: last receive error: {e}", C::NAME);
        }
        if let Some(e) = &l.last_error {
            eprintln!("emulator: {}: last send error: {e}", C::NAME);
        }
        let (extra, own) = self.chan.finish(&l.account, self.sent);
        Ok(PathReport {
            scenario: l.scenario,
            seed: self.seed,
            queue_order: l.queue_order,
            queue_capacity: l.queue_capacity,
            balanced: l.account.closes() && own,
            account: l.account,
            delivered_unsubscribed: self.unsubscribed,
            measures: l.measures,
            send_errors: l.send_errors,
            receive_errors: self.receive_errors,
            trace_overflowed: l.trace_overflowed,
            trace_path: l.trace_path,
            hlogs,
            extra,
        })
    }
}

/// Paths of any channel, as a lane holds its reverse paths: one fixed list
/// of these, polled once per turn.
pub trait Reverse {
    /// The channel's name.
    fn name(&self) -> &'static str;
    /// How the path ends.
    fn ending(&self) -> Ending;
    /// How often it is polled while the lane's reverse paths are quiet
    /// ([`Channel::QUIET_POLL_EVERY`]).
    fn quiet_poll_every(&self) -> u32;
    /// One poll ([`Path::poll`]); whether it took or released anything.
    fn poll(&mut self) -> bool;
    /// Whether the path has ended ([`Path::finished`]).
    fn finished(&mut self, now: u64, forward_end_ns: Option<u64>) -> bool;
    /// Sends the end marker now ([`Path::end`]).
    fn end(&mut self, now: u64);
    /// Keeps the trace writer off `core`.
    fn keep_trace_off_core(&self, core: usize) -> bool;
    /// Closes the path after the loop ([`Path::close`]).
    fn close(&mut self);
    /// Finishes the path; its report as JSON, under its channel's name.
    fn finish(self: Box<Self>, duration_ns: u64) -> Result<serde_json::Value, PathError>;
    /// The path itself, for those who know its channel (tests reach its
    /// ports through it).
    fn as_any_mut(&mut self) -> &mut dyn std::any::Any;
}

impl<C: Channel + 'static> Reverse for Path<C> {
    fn name(&self) -> &'static str {
        C::NAME
    }

    fn ending(&self) -> Ending {
        C::ENDING
    }

    fn quiet_poll_every(&self) -> u32 {
        C::QUIET_POLL_EVERY
    }

    #[inline]
    fn poll(&mut self) -> bool {
        let released = self.link.released();
        !Path::poll(self) || self.link.released() != released
    }

    fn finished(&mut self, now: u64, forward_end_ns: Option<u64>) -> bool {
        Path::finished(self, now, forward_end_ns)
    }

    fn end(&mut self, now: u64) {
        Path::end(self, now)
    }

    fn keep_trace_off_core(&self, core: usize) -> bool {
        Path::keep_trace_off_core(self, core)
    }

    fn close(&mut self) {
        Path::close(self)
    }

    fn finish(self: Box<Self>, duration_ns: u64) -> Result<serde_json::Value, PathError> {
        Ok(serde_json::to_value(Path::finish(*self, duration_ns)?)?)
    }

    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}
