//! `corrupt` (docs/spec.md §3.9): bit flips in the 124-byte ITP frame, in
//! one of two modes, given by exactly one parameter.
//!
//! - `p` (per frame): with probability `p` a frame has one bit flipped,
//!   chosen uniformly among the 992 bits of the frame. This is netem's
//!   `corrupt P`: one random bit of a random byte of the packet (netem's own
//!   correlation is not offered; see §3.7).
//! - `ber_per_byte = q` (per byte): each of the 124 bytes is in error
//!   independently with probability `q`, and a byte in error has one of its
//!   8 bits flipped, uniformly. The number of bytes in error, `K`, is
//!   Binomial(124, q). A verdict carries at most [`MAX_HITS`] flips: the
//!   first `min(K, 4)` bytes in error, in byte order, are flipped, and the
//!   rest of a frame with more than 4 (probability `P(K > 4)`, about
//!   2·10⁻⁷ at `q = 10⁻³` and 0.9% at `q = 10⁻²`;
//!   [`Corrupt::truncated_fraction_exact`]) are left as they are.
//!   Exact long-run values: frames corrupted `1 − (1 − q)^124`, flips per
//!   frame `E[min(K, 4)]` ([`Corrupt::flips_per_frame_exact`]).
//!
//! The core stays generic over what it carries, so the stage does not touch
//! bytes: its verdict is data, [`Verdict::Corrupt`] with the [`Hits`], the
//! indices of the bits to flip (`bit / 8` is the byte, `bit % 8` the bit
//! within it, least significant first). The frame goes on without delay. The
//! scenario collects the flips of every `corrupt` stage a frame passes (a
//! copy inherits those made before it was copied); whoever holds the bytes
//! applies them with [`crate::frame::flip_bits`].
//!
//! What the ITP checksum then sees is in [`crate::frame::checksum_catches`]:
//! one flip is caught exactly when it lands in a byte the checksum covers,
//! 44 of the 124 (`sequence`, the position increments, `buttonstate`,
//! `surgeon_mode` and the checksum itself); a flip in `pactyp`, `version`,
//! the rotations `Q*` or `grasp` passes unnoticed. So of the frames the
//! per-frame mode corrupts, exactly `44/124 = 11/31` are caught. (Several
//! flips in one frame can cancel in the checksum's sum, so the per-byte
//! mode's caught fraction has no closed form here; `scenario check`
//! measures it.)
//!
//! Draws. Per frame: one 53-bit uniform per frame, and for a corrupted frame
//! one uniform bit index (`random_range`, exact and portable). Per byte:
//! the gaps between bytes in error are geometric, drawn by inversion
//! (`⌊ln U / ln(1 − q)⌋`, one uniform per byte in error plus one), and each
//! byte in error draws its bit with `random_range(0..8)`.

use super::draw::{threshold, u53};
use super::{Model, ParamError, Probability, StageRng, Verdict};
use crate::frame::ITP_FRAME_LEN;
use rand::RngExt;
use serde::{Deserialize, Serialize};

/// The bits of one ITP frame, which a flip picks among.
pub const FRAME_BITS: u16 = (ITP_FRAME_LEN * 8) as u16;

/// The most flips one `corrupt` verdict carries.
pub const MAX_HITS: usize = 4;

/// The bits one `corrupt` stage flips in one frame (1 to [`MAX_HITS`]), in
/// increasing order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Hits {
    bits: [u16; MAX_HITS],
    len: u8,
}

impl Hits {
    /// One flip.
    pub const fn one(bit: u16) -> Hits {
        Hits { bits: [bit, 0, 0, 0], len: 1 }
    }

    /// The bit indices.
    #[inline]
    pub fn bits(&self) -> &[u16] {
        &self.bits[..usize::from(self.len)]
    }

    #[inline]
    fn push(&mut self, bit: u16) {
        self.bits[usize::from(self.len)] = bit;
        self.len += 1;
    }
}

/// A `corrupt` stage as written: exactly one of `p` and `ber_per_byte`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CorruptParams {
    /// Probability that a frame has one bit flipped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p: Option<Probability>,
    /// Probability that each byte of the frame is in error (one bit of it
    /// flipped), independently.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ber_per_byte: Option<Probability>,
}

impl CorruptParams {
    /// The per-frame mode.
    pub fn new(p: f64) -> Result<Self, ParamError> {
        Ok(CorruptParams { p: Some(super::units::probability("p", p)?), ber_per_byte: None })
    }

    /// The per-byte mode.
    pub fn per_byte(q: f64) -> Result<Self, ParamError> {
        Ok(CorruptParams { p: None, ber_per_byte: Some(super::units::probability("ber_per_byte", q)?) })
    }
}

/// How a stage picks its flips.
#[derive(Debug, Clone, Copy)]
enum Mode {
    PerFrame { threshold: u64, p: f64 },
    /// `ln_keep = ln(1 − q)` (−∞ for `q = 1`).
    PerByte { q: f64, ln_keep: f64 },
}

/// A validated `corrupt` stage.
#[derive(Debug, Clone)]
pub struct Corrupt {
    mode: Mode,
}

impl Corrupt {
    pub fn new(params: &CorruptParams) -> Result<Self, ParamError> {
        let checked = |field: &str, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(v)
            } else {
                Err(ParamError::new(field, format!("{v}: expected a rate in [0, 1]")))
            }
        };
        let mode = match (params.p, params.ber_per_byte) {
            (Some(p), None) => {
                let p = checked("p", p.get())?;
                Mode::PerFrame { threshold: threshold(p), p }
            }
            (None, Some(q)) => {
                let q = checked("ber_per_byte", q.get())?;
                Mode::PerByte { q, ln_keep: (1.0 - q).ln() }
            }
            (Some(_), Some(_)) => {
                return Err(ParamError::new("ber_per_byte", "give `p` (per frame) or `ber_per_byte` (per byte), not both"))
            }
            (None, None) => {
                return Err(ParamError::new("p", "missing: give `p` (a probability per frame) or `ber_per_byte` (per byte)"))
            }
        };
        Ok(Corrupt { mode })
    }

    /// The per-byte error probability, in the per-byte mode.
    pub fn ber_per_byte(&self) -> Option<f64> {
        match self.mode {
            Mode::PerByte { q, .. } => Some(q),
            Mode::PerFrame { .. } => None,
        }
    }

    /// The exact long-run fraction of frames reaching the stage that it
    /// corrupts: `p`, or `1 − (1 − q)^124`.
    pub fn corrupt_rate_exact(&self) -> f64 {
        match self.mode {
            Mode::PerFrame { p, .. } => p,
            Mode::PerByte { q, .. } => -(ITP_FRAME_LEN as f64 * (-q).ln_1p()).exp_m1(),
        }
    }

    /// The exact mean number of bits the stage flips per frame reaching it:
    /// `p`, or `E[min(K, 4)]` with `K ~ Binomial(124, q)`.
    pub fn flips_per_frame_exact(&self) -> f64 {
        match self.mode {
            Mode::PerFrame { p, .. } => p,
            Mode::PerByte { q, .. } => (0..=ITP_FRAME_LEN).map(|k| k.min(MAX_HITS) as f64 * binomial_pmf(ITP_FRAME_LEN, q, k)).sum(),
        }
    }

    /// The exact fraction of frames with more bytes in error than a verdict
    /// carries (`P(K > 4)`; 0 in the per-frame mode).
    pub fn truncated_fraction_exact(&self) -> f64 {
        match self.mode {
            Mode::PerFrame { .. } => 0.0,
            Mode::PerByte { q, .. } => (MAX_HITS + 1..=ITP_FRAME_LEN).map(|k| binomial_pmf(ITP_FRAME_LEN, q, k)).sum(),
        }
    }

    /// The exact fraction of the per-frame mode's flips that the ITP
    /// checksum catches: the covered bytes over all bytes, 44/124.
    pub fn caught_fraction_exact() -> f64 {
        crate::frame::CHECKSUM_COVERED_BYTES as f64 / ITP_FRAME_LEN as f64
    }

    /// [`Corrupt::caught_fraction_exact`] where it is exact for this stage
    /// (the per-frame mode: one flip per frame).
    pub fn caught_fraction_model(&self) -> Option<f64> {
        matches!(self.mode, Mode::PerFrame { .. }).then(Self::caught_fraction_exact)
    }

    #[inline]
    fn per_byte(q: f64, ln_keep: f64, rng: &mut StageRng) -> Verdict {
        let mut hits = Hits::default();
        let mut byte = 0usize;
        while hits.len < MAX_HITS as u8 {
            if q < 1.0 {
                // The bytes in error before the next one: geometric, by
                // inversion of a uniform in (0, 1].
                let u = 1.0 - rng.random::<f64>();
                let skip = (u.ln() / ln_keep).floor();
                if skip >= (ITP_FRAME_LEN - byte) as f64 {
                    break;
                }
                byte += skip as usize;
            }
            if byte >= ITP_FRAME_LEN {
                break;
            }
            hits.push(byte as u16 * 8 + rng.random_range(0..8u16));
            byte += 1;
        }
        if hits.len == 0 {
            Verdict::PASS
        } else {
            Verdict::Corrupt(hits)
        }
    }
}

/// `P(K = k)` for `K ~ Binomial(n, q)`, in logs (no overflow at n = 124).
fn binomial_pmf(n: usize, q: f64, k: usize) -> f64 {
    if q <= 0.0 {
        return f64::from(u8::from(k == 0));
    }
    if q >= 1.0 {
        return f64::from(u8::from(k == n));
    }
    let ln_choose: f64 = (1..=k).map(|i| ((n - k + i) as f64 / i as f64).ln()).sum();
    (ln_choose + k as f64 * q.ln() + (n - k) as f64 * (-q).ln_1p()).exp()
}

impl Model for Corrupt {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        match self.mode {
            Mode::PerFrame { threshold, .. } => {
                if u53(rng) < threshold {
                    Verdict::Corrupt(Hits::one(rng.random_range(0..FRAME_BITS)))
                } else {
                    Verdict::PASS
                }
            }
            Mode::PerByte { q, ln_keep } if q > 0.0 => Self::per_byte(q, ln_keep, rng),
            Mode::PerByte { .. } => Verdict::PASS,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn construction_and_bad_parameters() {
        assert_eq!(Corrupt::new(&CorruptParams::new(0.1).unwrap()).unwrap().corrupt_rate_exact(), 0.1);
        assert_eq!(CorruptParams::new(1.01).unwrap_err().field, "p");
        assert!(toml::from_str::<CorruptParams>("p = \"0.1%\"").is_ok());
        assert!(toml::from_str::<CorruptParams>("p = 2").is_err());
        assert!((Corrupt::caught_fraction_exact() - 11.0 / 31.0).abs() < 1e-15);
        // Per byte: exactly one of the two modes, rates in [0, 1].
        let q = Corrupt::new(&CorruptParams::per_byte(1e-3).unwrap()).unwrap();
        assert!((q.corrupt_rate_exact() - (1.0 - 0.999f64.powi(124))).abs() < 1e-15);
        assert_eq!(q.caught_fraction_model(), None);
        assert_eq!(CorruptParams::per_byte(1.5).unwrap_err().field, "ber_per_byte");
        assert_eq!(CorruptParams::per_byte(-0.1).unwrap_err().field, "ber_per_byte");
        let both = toml::from_str::<CorruptParams>("p = 0.1\nber_per_byte = 0.01").unwrap();
        assert_eq!(Corrupt::new(&both).unwrap_err().field, "ber_per_byte");
        let none = toml::from_str::<CorruptParams>("").unwrap();
        assert!(Corrupt::new(&none).unwrap_err().problem.contains("ber_per_byte"));
        assert!(toml::from_str::<CorruptParams>("ber_per_byte = 1.01").is_err());
        // The law's sums: the pmf sums to 1, and with q small the mean flips
        // are 124 q to first order.
        let total: f64 = (0..=124).map(|k| binomial_pmf(124, 0.3, k)).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        assert!((q.flips_per_frame_exact() - 0.124).abs() < 1e-6);
        assert!(q.truncated_fraction_exact() < 3e-7 && q.truncated_fraction_exact() > 1e-7);
    }

    #[test]
    fn per_byte_flips_one_bit_of_distinct_bytes_in_order() {
        let mut all = Corrupt::new(&CorruptParams::per_byte(1.0).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(8);
        match all.decide(0, &mut rng) {
            Verdict::Corrupt(h) => assert_eq!(h.bits().iter().map(|b| b / 8).collect::<Vec<_>>(), [0, 1, 2, 3]),
            other => panic!("{other:?}"),
        }
        let mut none = Corrupt::new(&CorruptParams::per_byte(0.0).unwrap()).unwrap();
        assert!((0..1000).all(|t| none.decide(t, &mut rng) == Verdict::PASS));
        let mut some = Corrupt::new(&CorruptParams::per_byte(0.05).unwrap()).unwrap();
        let mut corrupted = 0;
        for t in 0..10_000 {
            if let Verdict::Corrupt(h) = some.decide(t, &mut rng) {
                let bytes: Vec<u16> = h.bits().iter().map(|b| b / 8).collect();
                assert!(bytes.windows(2).all(|w| w[0] < w[1]) && bytes.iter().all(|&b| b < 124), "{bytes:?}");
                corrupted += 1;
            }
        }
        // 1 − 0.95^124 ≈ 99.8 % of frames have a byte flipped.
        assert!(corrupted > 9_000, "{corrupted} of 10 000 frames corrupted");
    }

    #[test]
    fn every_flip_is_inside_the_frame() {
        let mut c = Corrupt::new(&CorruptParams::new(1.0).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(5);
        let mut seen = [false; FRAME_BITS as usize];
        for t in 0..100_000 {
            match c.decide(t, &mut rng) {
                Verdict::Corrupt(h) => seen[usize::from(h.bits()[0])] = true,
                other => panic!("{other:?}"),
            }
        }
        assert!(seen.iter().all(|s| *s), "every bit is reachable");
    }

    #[test]
    fn value_stability() {
        let mut c = Corrupt::new(&CorruptParams::new(0.5).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        let got: Vec<Verdict> = (0..8).map(|t| c.decide(t, &mut rng)).collect();
        assert_eq!(got, PINNED);
    }
    const PINNED: [Verdict; 8] = [
        Verdict::PASS,
        Verdict::Corrupt(Hits::one(976)),
        Verdict::PASS,
        Verdict::PASS,
        Verdict::PASS,
        Verdict::Corrupt(Hits::one(600)),
        Verdict::Corrupt(Hits::one(925)),
        Verdict::PASS,
    ];
}
