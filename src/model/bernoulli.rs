//! `bernoulli` (docs/spec.md §3.1): each frame is dropped independently with
//! probability `p`.

use super::{Model, ParamError, Probability, StageRng, Verdict};
use rand::RngExt;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BernoulliParams {
    /// Drop probability per frame.
    pub p: Probability,
}

impl BernoulliParams {
    /// Drops each frame with probability `p`.
    pub fn new(p: f64) -> Result<Self, ParamError> {
        Ok(BernoulliParams { p: super::units::probability("p", p)? })
    }
}

#[derive(Debug, Clone)]
pub struct Bernoulli {
    dist: rand::distr::Bernoulli,
    p: f64,
}

impl Bernoulli {
    pub fn new(params: &BernoulliParams) -> Result<Self, ParamError> {
        let p = params.p.get();
        let dist = rand::distr::Bernoulli::new(p)
            .map_err(|e| ParamError::new("p", format!("{p}: {e}; expected a probability in [0, 1]")))?;
        Ok(Bernoulli { dist, p })
    }

    pub fn loss_rate_exact(&self) -> f64 {
        self.p
    }
}

impl Model for Bernoulli {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        if rng.sample(self.dist) {
            Verdict::Drop
        } else {
            Verdict::PASS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn model(p: f64) -> Bernoulli {
        Bernoulli::new(&BernoulliParams { p: Probability::new(p).unwrap() }).unwrap()
    }

    #[test]
    fn construction_and_loss() {
        assert_eq!(model(0.25).loss_rate_exact(), 0.25);
        let p: BernoulliParams = toml::from_str("p = \"30%\"").unwrap();
        assert!((Bernoulli::new(&p).unwrap().loss_rate_exact() - 0.3).abs() < 1e-15);
        assert!(toml::from_str::<BernoulliParams>("p = 1.2").is_err());
        assert!(toml::from_str::<BernoulliParams>("p = 0.1\nq = 0.2").is_err());
    }

    #[test]
    fn certain_outcomes() {
        let mut rng = StageRng::seed_from_u64(1);
        let (mut never, mut always) = (model(0.0), model(1.0));
        assert!((0..10_000).all(|t| never.decide(t, &mut rng) == Verdict::PASS));
        assert!((0..10_000).all(|t| always.decide(t, &mut rng) == Verdict::Drop));
    }

    #[test]
    fn value_stability() {
        let mut m = model(0.3);
        let mut rng = StageRng::seed_from_u64(42);
        let fates: String =
            (0..64).map(|t| if m.decide(t, &mut rng) == Verdict::Drop { 'x' } else { '.' }).collect();
        assert_eq!(fates, PINNED_FATES);
    }
    const PINNED_FATES: &str = "......x.x....x..xx..x....x....x..x.......x..x....x.....x.x.x....";
}
