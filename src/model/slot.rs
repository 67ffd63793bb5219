//! `slot` (docs/spec.md §3.11): netem's `slot MIN MAX [packets N] [bytes B]`,
//! releases in bursts at slot boundaries, as Wi-Fi and LTE schedulers do.
//!
//! The stage keeps the time `slot_next` of the next slot and the budget left
//! in it. Per frame reaching the stage at `t`, in arrival order:
//!
//! 1. if `slot_next < t` (the slot passed unused while nothing waited), a new
//!    slot opens `S ~ U[min_ms, max_ms)` after `t`, with a full budget;
//! 2. the frame is released at `slot_next` (never before `t`);
//! 3. it uses one packet and [`FRAME_BYTES`] bytes of the budget; once the
//!    packets or the bytes are used up, the next slot opens `S` after this
//!    one, with a full budget.
//!
//! This is netem's dequeue (`get_slot_next` after a stale slot, and after a
//! slot's budget runs out); a frame counts 124 bytes, the ITP frame (netem
//! counts the whole packet, headers included). Without `packets` and
//! `bytes` a slot has no budget limit: everything waiting goes at its
//! boundary. Releases keep arrival order (a frame that arrives earlier than
//! one before it, after an upstream reorder, is released with it).
//!
//! Long-run: slots are `(min_ms + max_ms)/2` apart on average while frames
//! wait, and carry at most `packets` (and `⌈bytes/124⌉`) frames, so the stage
//! passes at most `packets / E[S]` frames per ms; a frame arriving to an
//! idle stage waits a whole `S`. Draws: one uniform per slot opened.

use super::units::{at_most_ms, ms_to_ns, MAX_DURATION_MS};
use super::{Millis, Model, ParamError, StageRng, Verdict};
use rand::RngExt;
use serde::{Deserialize, Serialize};

/// The bytes one frame uses of a slot's budget: the ITP frame.
pub const FRAME_BYTES: u64 = crate::frame::ITP_FRAME_LEN as u64;

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SlotParams {
    /// The shortest spacing of slots.
    pub min_ms: Millis,
    /// The longest spacing (≥ `min_ms`; equal for fixed slots).
    pub max_ms: Millis,
    /// The most frames one slot releases (unlimited when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub packets: Option<u64>,
    /// The most bytes one slot releases, 124 per frame (unlimited when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<u64>,
}

impl SlotParams {
    pub fn new(min_ms: f64, max_ms: f64, packets: Option<u64>, bytes: Option<u64>) -> Result<Self, ParamError> {
        Ok(SlotParams {
            min_ms: super::units::millis("min_ms", min_ms)?,
            max_ms: super::units::millis("max_ms", max_ms)?,
            packets,
            bytes,
        })
    }
}

/// A validated `slot` stage and its state.
#[derive(Debug, Clone)]
pub struct Slot {
    min_ms: f64,
    width_ms: f64,
    packets: u64,
    bytes: u64,
    slot_next_ns: u64,
    packets_left: u64,
    bytes_left: u64,
    opened: u64,
}

impl Slot {
    pub fn new(params: &SlotParams) -> Result<Self, ParamError> {
        let (min_ms, max_ms) = (params.min_ms.get(), params.max_ms.get());
        at_most_ms("min_ms", min_ms, MAX_DURATION_MS, "one hour")?;
        at_most_ms("max_ms", max_ms, MAX_DURATION_MS, "one hour")?;
        if min_ms > max_ms {
            return Err(ParamError::new(
                "max_ms",
                format!("{max_ms} ms is below min_ms = {min_ms} ms: expected min_ms ≤ max_ms (equal for fixed slots)"),
            ));
        }
        if max_ms == 0.0 {
            return Err(ParamError::new("max_ms", "0 ms: slots need a spacing above 0 (remove the stage for none)"));
        }
        for (field, v) in [("packets", params.packets), ("bytes", params.bytes)] {
            if v == Some(0) {
                return Err(ParamError::new(field, "0: a slot must release something; expected at least 1 (or leave it out for no limit)"));
            }
        }
        Ok(Slot {
            min_ms,
            width_ms: max_ms - min_ms,
            packets: params.packets.unwrap_or(u64::MAX),
            bytes: params.bytes.unwrap_or(u64::MAX),
            slot_next_ns: 0,
            packets_left: 0,
            bytes_left: 0,
            opened: 0,
        })
    }

    /// The exact mean slot spacing `E[S] = (min_ms + max_ms)/2`, in ms.
    pub fn spacing_ms_mean_exact(&self) -> f64 {
        self.min_ms + self.width_ms / 2.0
    }

    /// The most frames one slot releases.
    pub fn frames_per_slot_max(&self) -> u64 {
        self.packets.min(self.bytes.div_ceil(FRAME_BYTES))
    }

    /// Slots opened so far.
    pub fn slots_opened(&self) -> u64 {
        self.opened
    }

    fn open(&mut self, from_ns: u64, rng: &mut StageRng) {
        let s_ms = self.min_ms + if self.width_ms > 0.0 { rng.random::<f64>() * self.width_ms } else { 0.0 };
        self.slot_next_ns = from_ns.saturating_add(ms_to_ns(s_ms));
        self.packets_left = self.packets;
        self.bytes_left = self.bytes;
        self.opened += 1;
    }
}

impl Model for Slot {
    #[inline]
    fn decide(&mut self, t_ns: u64, rng: &mut StageRng) -> Verdict {
        if self.slot_next_ns < t_ns || self.opened == 0 {
            self.open(t_ns, rng);
        }
        let release_ns = self.slot_next_ns.max(t_ns);
        self.packets_left -= 1;
        self.bytes_left = self.bytes_left.saturating_sub(FRAME_BYTES);
        if self.packets_left == 0 || self.bytes_left == 0 {
            self.open(release_ns, rng);
        }
        Verdict::Pass { delay_ns: release_ns - t_ns }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn slot(min_ms: f64, max_ms: f64, packets: Option<u64>, bytes: Option<u64>) -> Slot {
        Slot::new(&SlotParams::new(min_ms, max_ms, packets, bytes).unwrap()).unwrap()
    }

    fn release(s: &mut Slot, t: u64, rng: &mut StageRng) -> u64 {
        match s.decide(t, rng) {
            Verdict::Pass { delay_ns } => t + delay_ns,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_parameters_name_their_field() {
        let e = Slot::new(&SlotParams::new(5.0, 2.0, None, None).unwrap()).unwrap_err();
        assert_eq!(e.field, "max_ms");
        assert!(e.problem.contains("min_ms ≤ max_ms"), "{e}");
        assert_eq!(Slot::new(&SlotParams::new(1.0, 2.0, Some(0), None).unwrap()).unwrap_err().field, "packets");
        assert_eq!(Slot::new(&SlotParams::new(1.0, 2.0, None, Some(0)).unwrap()).unwrap_err().field, "bytes");
        assert_eq!(Slot::new(&SlotParams::new(0.0, 0.0, None, None).unwrap()).unwrap_err().field, "max_ms");
        assert_eq!(Slot::new(&SlotParams::new(1.0, 4e6, None, None).unwrap()).unwrap_err().field, "max_ms");
        assert_eq!(slot(2.0, 4.0, None, None).spacing_ms_mean_exact(), 3.0);
        assert_eq!(slot(2.0, 4.0, Some(10), Some(500)).frames_per_slot_max(), 5);
    }

    #[test]
    fn fixed_slots_release_in_bursts_at_their_boundaries() {
        // Slots every 10 ms, 3 frames each; frames every 1 ms from t = 0.
        let mut s = slot(10.0, 10.0, Some(3), None);
        let mut rng = StageRng::seed_from_u64(1);
        let before = rng.clone();
        let releases: Vec<u64> = (0..9).map(|i| release(&mut s, i * 1_000_000, &mut rng) / 1_000_000).collect();
        // The first slot opens 10 ms after the first frame; each slot takes 3.
        assert_eq!(releases, [10, 10, 10, 20, 20, 20, 30, 30, 30]);
        assert_eq!(rng, before, "fixed slots draw nothing");
        // An idle stage: a frame long after waits a whole slot.
        assert_eq!(release(&mut s, 100_000_000, &mut rng), 110_000_000);
    }

    #[test]
    fn a_byte_budget_counts_whole_frames() {
        // 300 bytes: 124 + 124 leaves 52 > 0, a third frame empties it.
        let mut s = slot(5.0, 5.0, None, Some(300));
        let mut rng = StageRng::seed_from_u64(1);
        let r: Vec<u64> = (0..6).map(|_| release(&mut s, 0, &mut rng) / 1_000_000).collect();
        assert_eq!(r, [5, 5, 5, 10, 10, 10]);
    }

    #[test]
    fn value_stability() {
        let mut s = slot(1.0, 9.0, Some(2), None);
        let mut rng = StageRng::seed_from_u64(42);
        let r: Vec<u64> = (0..8).map(|i| release(&mut s, i * 1_000_000, &mut rng)).collect();
        assert_eq!(r, PINNED);
    }
    const PINNED: [u64; 8] = [7514441, 7514441, 11065009, 11065009, 19936162, 19936162, 26545247, 26545247];
}
