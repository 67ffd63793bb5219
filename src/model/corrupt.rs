//! `corrupt` (docs/spec.md §3.9): with probability `p` a frame has one bit
//! flipped, chosen uniformly among the 992 bits of the 124-byte ITP frame.
//!
//! The core stays generic over what it carries, so the stage does not touch
//! bytes: its verdict is data, [`Verdict::Corrupt`]`{ bit }`, the index of the
//! bit to flip (`bit / 8` is the byte, `bit % 8` the bit within it, least
//! significant first). The frame goes on without delay. The scenario collects
//! the flips of every `corrupt` stage a frame passes (a copy inherits those
//! made before it was copied); whoever holds the bytes applies them with
//! [`crate::frame::flip_bits`].
//!
//! This is netem's `corrupt P`: one random bit of a random byte of the packet
//! (netem's own correlation is not offered; see §3.7). What the ITP checksum
//! then sees is in [`crate::frame::checksum_catches`]: one flip is caught
//! exactly when it lands in a byte the checksum covers, 44 of the 124
//! (`sequence`, the position increments, `buttonstate`, `surgeon_mode` and
//! the checksum itself); a flip in `pactyp`, `version`, the rotations `Q*` or
//! `grasp` passes unnoticed. So of the frames one stage corrupts, exactly
//! `44/124 = 11/31` are caught.
//!
//! Long-run: corrupted frames per frame reaching the stage `= p`. Draws: one
//! 53-bit uniform per frame, and for a corrupted frame one uniform bit index
//! (`random_range`, exact and portable).

use super::draw::{threshold, u53};
use super::{Model, ParamError, Probability, StageRng, Verdict};
use crate::frame::ITP_FRAME_LEN;
use rand::RngExt;
use serde::{Deserialize, Serialize};

/// The bits of one ITP frame, which a flip picks among.
pub const FRAME_BITS: u16 = (ITP_FRAME_LEN * 8) as u16;

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CorruptParams {
    /// Probability that a frame has one bit flipped.
    pub p: Probability,
}

impl CorruptParams {
    pub fn new(p: f64) -> Result<Self, ParamError> {
        Ok(CorruptParams { p: super::units::probability("p", p)? })
    }
}

/// A validated `corrupt` stage.
#[derive(Debug, Clone)]
pub struct Corrupt {
    threshold: u64,
    p: f64,
}

impl Corrupt {
    pub fn new(params: &CorruptParams) -> Result<Self, ParamError> {
        let p = params.p.get();
        if !(0.0..=1.0).contains(&p) {
            return Err(ParamError::new("p", format!("{p}: expected a corruption probability in [0, 1]")));
        }
        Ok(Corrupt { threshold: threshold(p), p })
    }

    /// The exact long-run fraction of frames reaching the stage that it
    /// corrupts.
    pub fn corrupt_rate_exact(&self) -> f64 {
        self.p
    }

    /// The exact fraction of this stage's flips that the ITP checksum
    /// catches: the covered bytes over all bytes, 44/124.
    pub fn caught_fraction_exact() -> f64 {
        crate::frame::CHECKSUM_COVERED_BYTES as f64 / ITP_FRAME_LEN as f64
    }
}

impl Model for Corrupt {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        if u53(rng) < self.threshold {
            Verdict::Corrupt { bit: rng.random_range(0..FRAME_BITS) }
        } else {
            Verdict::PASS
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
    }

    #[test]
    fn every_flip_is_inside_the_frame() {
        let mut c = Corrupt::new(&CorruptParams::new(1.0).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(5);
        let mut seen = [false; FRAME_BITS as usize];
        for t in 0..100_000 {
            match c.decide(t, &mut rng) {
                Verdict::Corrupt { bit } => seen[usize::from(bit)] = true,
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
        Verdict::Corrupt { bit: 976 },
        Verdict::PASS,
        Verdict::PASS,
        Verdict::PASS,
        Verdict::Corrupt { bit: 600 },
        Verdict::Corrupt { bit: 925 },
        Verdict::PASS,
    ];
}
