//! Synthetic console motion: a seeded stream of ITP frames that looks like a
//! person doing a bimanual peg transfer.
//!
//! Contract: sans-IO and clockless. Frame `k` stands for time `k / rate_hz`;
//! the caller decides when to send it. The same parameters and seed give the
//! same frames, bit for bit, on every platform (the generator is
//! Xoshiro256++ and the arithmetic is plain IEEE `f64`). Nothing allocates
//! per frame.
//!
//! The model, per arm, repeats a pick-and-place cycle: a point-to-point move
//! with a minimum-jerk profile, a grasp ramp (closing after an approach,
//! opening after a carry), then a pause. Moves go between random targets in a
//! box around the start, a few centimetres apart, at peak speeds of a few
//! cm/s, and turn the wrist a little on the way. Now and then the surgeon
//! releases the clutch (`surgeon_mode` 0) for some hundreds of ms, but only
//! while both arms are still, as a person repositions their hands between
//! moves; a released clutch freezes both arms.
//!
//! The frame fields follow what the shipped dVTrainer capture shows:
//!
//! - positions are integer increments in the capture's unit (about 10 µm,
//!   see [`crate::kinematics`]), emitted with the rounding remainder carried
//!   to the next frame so that the increments sum to the true displacement;
//! - rotation increments are integer-valued `Qx, Qy, Qz` (mostly 0, now and
//!   then ±1, carried the same way) with `Qw` = 1, as in the capture;
//! - the grasp is absolute and moves in steps of 30, and `buttonstate` repeats
//!   the grasp, as the capture's console does;
//! - `pactyp` and `version` are 0, the checksum is filled in.
//!
//! [`MotionParams::peg_transfer`] is tuned so that the mean motion per second
//! and the share of clutch-released frames match the capture (see the tests).

use crate::frame::{ItpFrame, ARMS, SURGEON_DISENGAGED, SURGEON_ENGAGED};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

/// The random generator of the motion model.
pub type MotionRng = Xoshiro256PlusPlus;

/// Grasp commands change in steps of this size, as in the shipped capture.
pub const GRASP_STEP: i32 = 30;

/// Attempts at drawing a move target at an acceptable distance before the
/// last draw is taken as is.
const TARGET_ATTEMPTS: usize = 32;

/// The highest frame rate a console streams at, Hz (a frame a microsecond).
pub const MAX_RATE_HZ: f64 = 1e6;

/// Parameters of the motion model. Ranges are `[min, max]` pairs drawn
/// uniformly; positions are in ITP position units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionParams {
    /// Frames per second.
    pub rate_hz: f64,
    /// Sequence number of the first frame.
    pub sequence_start: u32,
    /// Half-widths of the box, around each arm's start, that targets lie in.
    pub workspace_units: [f64; 3],
    /// Length of one move.
    pub move_units: [f64; 2],
    /// Peak speed of one move (the mean speed is 1/1.875 of it).
    pub peak_speed_units_per_s: [f64; 2],
    /// Largest wrist rotation per move, per component, in rotation units.
    pub rotation_per_move: f64,
    /// Pause after each grasp ramp.
    pub dwell_ms: [f64; 2],
    /// Probability that a move ends with a grasp ramp (closing on an object
    /// or letting it go); otherwise it was an adjustment and the grasp stays.
    pub grasp_probability: f64,
    /// Duration of a grasp ramp.
    pub grasp_ramp_ms: f64,
    /// Grasp command when open.
    pub grasp_open: [i32; 2],
    /// Grasp command when closed on an object.
    pub grasp_closed: [i32; 2],
    /// Time from the end of one clutch release to the next one becoming due.
    pub clutch_interval_ms: [f64; 2],
    /// Duration of one clutch release.
    pub clutch_release_ms: [f64; 2],
}

impl MotionParams {
    /// A peg transfer at `rate_hz`, tuned to the shipped capture.
    pub fn peg_transfer(rate_hz: f64) -> MotionParams {
        MotionParams {
            rate_hz,
            sequence_start: 0,
            workspace_units: [3000.0, 3500.0, 2000.0],
            move_units: [1500.0, 5800.0],
            peak_speed_units_per_s: [2000.0, 8000.0],
            rotation_per_move: 100.0,
            dwell_ms: [600.0, 3200.0],
            grasp_probability: 0.5,
            grasp_ramp_ms: 300.0,
            grasp_open: [0, 150],
            grasp_closed: [800, 2600],
            clutch_interval_ms: [20_000.0, 50_000.0],
            clutch_release_ms: [400.0, 1500.0],
        }
    }

    /// Checks every parameter; the generator relies on the result.
    pub fn validate(&self) -> Result<(), MotionParamError> {
        fn positive(field: &'static str, v: f64) -> Result<(), MotionParamError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(MotionParamError::new(field, format!("{v}; expected a positive, finite number")))
            }
        }
        fn range(field: &'static str, r: [f64; 2], zero_ok: bool) -> Result<(), MotionParamError> {
            let ok_lo = r[0].is_finite() && (r[0] > 0.0 || (zero_ok && r[0] == 0.0));
            if ok_lo && r[1].is_finite() && r[0] <= r[1] {
                Ok(())
            } else {
                let lo = if zero_ok { "non-negative" } else { "positive" };
                Err(MotionParamError::new(
                    field,
                    format!("[{}, {}]; expected finite [min, max] with {lo} min ≤ max", r[0], r[1]),
                ))
            }
        }
        positive("rate_hz", self.rate_hz)?;
        if self.rate_hz > MAX_RATE_HZ {
            return Err(MotionParamError::new("rate_hz", format!("{}; expected at most 1e6 Hz", self.rate_hz)));
        }
        for (k, &w) in self.workspace_units.iter().enumerate() {
            positive(["workspace_units[0]", "workspace_units[1]", "workspace_units[2]"][k], w)?;
        }
        range("move_units", self.move_units, false)?;
        range("peak_speed_units_per_s", self.peak_speed_units_per_s, false)?;
        if !(self.rotation_per_move.is_finite() && self.rotation_per_move >= 0.0) {
            return Err(MotionParamError::new(
                "rotation_per_move",
                format!("{}; expected a non-negative, finite number", self.rotation_per_move),
            ));
        }
        range("dwell_ms", self.dwell_ms, true)?;
        if !(0.0..=1.0).contains(&self.grasp_probability) {
            return Err(MotionParamError::new(
                "grasp_probability",
                format!("{}; expected a probability in [0, 1]", self.grasp_probability),
            ));
        }
        positive("grasp_ramp_ms", self.grasp_ramp_ms)?;
        for (field, r) in [("grasp_open", self.grasp_open), ("grasp_closed", self.grasp_closed)] {
            if r[0] > r[1] {
                return Err(MotionParamError::new(field, format!("[{}, {}]; expected min ≤ max", r[0], r[1])));
            }
        }
        range("clutch_interval_ms", self.clutch_interval_ms, false)?;
        range("clutch_release_ms", self.clutch_release_ms, false)?;
        Ok(())
    }
}

impl Default for MotionParams {
    /// A peg transfer at the nominal 1 kHz.
    fn default() -> Self {
        MotionParams::peg_transfer(1000.0)
    }
}

/// A motion parameter that failed validation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("motion parameter `{field}`: {problem}")]
pub struct MotionParamError {
    /// The parameter, as named in [`MotionParams`].
    pub field: &'static str,
    /// What is wrong and what would be accepted.
    pub problem: String,
}

impl MotionParamError {
    fn new(field: &'static str, problem: String) -> Self {
        MotionParamError { field, problem }
    }
}

/// Minimum-jerk position profile on `[0, 1]`: `10τ³ − 15τ⁴ + 6τ⁵`.
#[inline]
fn min_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Dwell,
    Move,
    Grasp,
}

/// One arm: a continuous pose and the integer pose already emitted.
#[derive(Debug, Clone)]
struct Arm {
    phase: Phase,
    elapsed_s: f64,
    duration_s: f64,
    /// Move start and end, relative to the arm's start.
    from: [f64; 3],
    to: [f64; 3],
    rot_from: [f64; 3],
    rot_to: [f64; 3],
    grasp_from: f64,
    grasp_to: f64,
    /// Whether the grasper holds an object (the next move is a carry).
    holding: bool,
    /// Current continuous pose.
    position: [f64; 3],
    rotation: [f64; 3],
    grasp: f64,
    /// Pose already sent, in whole units.
    position_sent: [i64; 3],
    rotation_sent: [i64; 3],
}

impl Arm {
    fn new(grasp: f64, dwell_s: f64) -> Arm {
        Arm {
            phase: Phase::Dwell,
            elapsed_s: 0.0,
            duration_s: dwell_s,
            from: [0.0; 3],
            to: [0.0; 3],
            rot_from: [0.0; 3],
            rot_to: [0.0; 3],
            grasp_from: grasp,
            grasp_to: grasp,
            holding: false,
            position: [0.0; 3],
            rotation: [0.0; 3],
            grasp,
            position_sent: [0; 3],
            rotation_sent: [0; 3],
        }
    }

    fn start_move(&mut self, p: &MotionParams, rng: &mut MotionRng) {
        let mut to = self.position;
        for _ in 0..TARGET_ATTEMPTS {
            to = core::array::from_fn(|k| rng.random_range(-p.workspace_units[k]..=p.workspace_units[k]));
            let d = distance(self.position, to);
            if d >= p.move_units[0] && d <= p.move_units[1] {
                break;
            }
        }
        let speed_peak = rng.random_range(p.peak_speed_units_per_s[0]..=p.peak_speed_units_per_s[1]);
        self.from = self.position;
        self.to = to;
        self.rot_from = self.rotation;
        let r = p.rotation_per_move;
        self.rot_to = core::array::from_fn(|k| self.rotation[k] + rng.random_range(-r..=r));
        // A minimum-jerk move peaks at 1.875 times its mean speed.
        self.duration_s = (1.875 * distance(self.from, self.to) / speed_peak).max(1e-3);
        self.phase = Phase::Move;
        self.elapsed_s = 0.0;
    }

    fn start_grasp(&mut self, p: &MotionParams, rng: &mut MotionRng) {
        self.holding = !self.holding;
        let r = if self.holding { p.grasp_closed } else { p.grasp_open };
        self.grasp_from = self.grasp;
        self.grasp_to = rng.random_range(r[0]..=r[1]) as f64;
        self.duration_s = p.grasp_ramp_ms * 1e-3;
        self.phase = Phase::Grasp;
        self.elapsed_s = 0.0;
    }

    fn start_dwell(&mut self, p: &MotionParams, rng: &mut MotionRng) {
        self.duration_s = rng.random_range(p.dwell_ms[0]..=p.dwell_ms[1]) * 1e-3;
        self.phase = Phase::Dwell;
        self.elapsed_s = 0.0;
    }

    /// Advances by `dt_s`. A dwelling arm with `hold` set keeps dwelling
    /// (a clutch release is waiting for both arms to be still).
    fn step(&mut self, dt_s: f64, hold: bool, p: &MotionParams, rng: &mut MotionRng) {
        self.elapsed_s += dt_s;
        let tau = self.elapsed_s / self.duration_s;
        match self.phase {
            Phase::Move => {
                let s = min_jerk(tau);
                for k in 0..3 {
                    self.position[k] = self.from[k] + (self.to[k] - self.from[k]) * s;
                    self.rotation[k] = self.rot_from[k] + (self.rot_to[k] - self.rot_from[k]) * s;
                }
                if tau >= 1.0 {
                    if rng.random_bool(p.grasp_probability) {
                        self.start_grasp(p, rng);
                    } else {
                        self.start_dwell(p, rng);
                    }
                }
            }
            Phase::Grasp => {
                self.grasp = self.grasp_from + (self.grasp_to - self.grasp_from) * min_jerk(tau);
                if tau >= 1.0 {
                    self.start_dwell(p, rng);
                }
            }
            Phase::Dwell => {
                if tau >= 1.0 && !hold {
                    self.start_move(p, rng);
                }
            }
        }
    }

    fn is_still(&self) -> bool {
        self.phase == Phase::Dwell
    }

    /// The integer increments that bring the sent pose to the current one.
    fn emit(&mut self) -> ([i32; 3], [f64; 3]) {
        let mut inc = [0i32; 3];
        let mut rot = [0f64; 3];
        for k in 0..3 {
            let target = self.position[k].round() as i64;
            inc[k] = (target - self.position_sent[k]) as i32;
            self.position_sent[k] = target;
            let target = self.rotation[k].round() as i64;
            rot[k] = (target - self.rotation_sent[k]) as f64;
            self.rotation_sent[k] = target;
        }
        (inc, rot)
    }

    fn grasp_command(&self) -> i32 {
        (self.grasp / GRASP_STEP as f64).round() as i32 * GRASP_STEP
    }
}

#[inline]
fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d: [f64; 3] = core::array::from_fn(|k| a[k] - b[k]);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// The seeded stream of synthetic console frames. An endless iterator.
#[derive(Debug, Clone)]
pub struct MotionGenerator {
    params: MotionParams,
    rng: MotionRng,
    dt_s: f64,
    frame_index: u64,
    arms: [Arm; ARMS],
    /// Time a clutch release becomes due (it waits for both arms to be still).
    clutch_due_s: f64,
    /// End of the clutch release in progress, if any.
    released_until_s: Option<f64>,
}

impl MotionGenerator {
    /// A generator at frame 0, seeded with `seed`.
    pub fn new(params: MotionParams, seed: u64) -> Result<MotionGenerator, MotionParamError> {
        params.validate()?;
        let mut rng = MotionRng::seed_from_u64(seed);
        let arms = core::array::from_fn(|_| {
            let grasp = rng.random_range(params.grasp_open[0]..=params.grasp_open[1]) as f64;
            let dwell_s = rng.random_range(params.dwell_ms[0]..=params.dwell_ms[1]) * 1e-3;
            Arm::new(grasp, dwell_s)
        });
        let clutch_due_s =
            rng.random_range(params.clutch_interval_ms[0]..=params.clutch_interval_ms[1]) * 1e-3;
        Ok(MotionGenerator {
            dt_s: 1.0 / params.rate_hz,
            params,
            rng,
            frame_index: 0,
            arms,
            clutch_due_s,
            released_until_s: None,
        })
    }

    /// The parameters it runs with.
    pub fn params(&self) -> &MotionParams {
        &self.params
    }

    /// Frames produced so far (also the index of the next one).
    pub fn frames_generated(&self) -> u64 {
        self.frame_index
    }

    /// Time of frame `index` from the start, ns, at the configured rate.
    pub fn frame_time_ns(&self, index: u64) -> u64 {
        (index as f64 * 1e9 / self.params.rate_hz).round() as u64
    }

    /// The next frame.
    pub fn next_frame(&mut self) -> ItpFrame {
        let t_s = self.frame_index as f64 * self.dt_s;
        let p = &self.params;

        let released = match self.released_until_s {
            Some(until_s) if t_s < until_s => true,
            Some(_) => {
                self.released_until_s = None;
                self.clutch_due_s =
                    t_s + self.rng.random_range(p.clutch_interval_ms[0]..=p.clutch_interval_ms[1]) * 1e-3;
                false
            }
            None if t_s >= self.clutch_due_s && self.arms.iter().all(Arm::is_still) => {
                let release_s = self.rng.random_range(p.clutch_release_ms[0]..=p.clutch_release_ms[1]) * 1e-3;
                self.released_until_s = Some(t_s + release_s);
                true
            }
            None => false,
        };

        let mut frame = ItpFrame {
            sequence: p.sequence_start.wrapping_add(self.frame_index as u32),
            qw: [1.0; ARMS],
            surgeon_mode: if released { SURGEON_DISENGAGED } else { SURGEON_ENGAGED },
            ..ItpFrame::default()
        };
        let hold = t_s >= self.clutch_due_s;
        for (arm, state) in self.arms.iter_mut().enumerate() {
            if !released {
                state.step(self.dt_s, hold, p, &mut self.rng);
                let (inc, rot) = state.emit();
                frame.delx[arm] = inc[0];
                frame.dely[arm] = inc[1];
                frame.delz[arm] = inc[2];
                frame.qx[arm] = rot[0];
                frame.qy[arm] = rot[1];
                frame.qz[arm] = rot[2];
            }
            frame.grasp[arm] = state.grasp_command();
        }
        frame.buttonstate = frame.grasp;
        self.frame_index += 1;
        frame.with_checksum()
    }
}

impl Iterator for MotionGenerator {
    type Item = ItpFrame;

    fn next(&mut self) -> Option<ItpFrame> {
        Some(self.next_frame())
    }
}

#[cfg(test)]
mod tests;

