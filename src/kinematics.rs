//! Integrating ITP commands into poses, as the simulator does (docs/spec.md §2, §6).
//!
//! Contract:
//!
//! - A frame's commands apply only while its `surgeon_mode` is engaged (1);
//!   a released clutch freezes the robot. This holds frame by frame, so the
//!   order in which frames arrive does not change the pose they add up to.
//! - Position and rotation are incremental: each applied frame adds its
//!   increments, and a lost increment is never recovered. Positions are summed
//!   exactly as integers; rotations as the sum of the `Qx, Qy, Qz` components
//!   (the small-angle composition of increments), in the frame's own units.
//! - The grasp is absolute: an applied frame sets it.
//! - Nothing here reads a clock: each frame comes with its time in ns. Nothing
//!   allocates per frame.
//!
//! An [`Integrator`] follows one stream. [`Kinematics`] pairs two, the console
//! side (every frame sent) and the robot side (every frame received), and
//! measures how far the robot's pose diverges from the console's.
//!
//! # Position unit
//!
//! ITP positions are integers. The shipped dVTrainer capture implies one unit
//! is about 10 µm ([`UNIT_MM`] = 0.01 mm): integrated over the recording, each
//! arm's position spans 4 to 10 thousand units per axis, which is 4–10 cm at
//! 10 µm (the size of a peg-transfer board), and its fastest moves reach 8 to
//! 10 thousand units/s over 100 ms, i.e. 8–10 cm/s. Read as micrometres (the Raven II
//! convention), the same task would fit within one centimetre, which a
//! peg transfer does not. The unit is a setting ([`KinematicsConfig::unit_mm`]);
//! only the millimetre figures depend on it.

use crate::frame::{ItpFrame, ARMS};
use serde::{Deserialize, Serialize};

/// Millimetres per ITP position unit inferred from the shipped capture.
pub const UNIT_MM: f64 = 0.01;

/// Default stall threshold: a gap between frames longer than this is a stall.
pub const STALL_THRESHOLD_NS_DEFAULT: u64 = 10_000_000;

/// What to do with a frame whose checksum does not match its fields. Either
/// way the mismatch is counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChecksumPolicy {
    /// Apply it like any other frame.
    #[default]
    Apply,
    /// Ignore it: it neither moves the arms nor ends a stall.
    Discard,
}

/// Settings of the integrator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KinematicsConfig {
    /// A gap between consecutive frames longer than this is a stall.
    pub stall_threshold_ns: u64,
    /// Millimetres per ITP position unit.
    pub unit_mm: f64,
    /// Treatment of frames whose checksum does not match.
    pub checksum_policy: ChecksumPolicy,
}

impl Default for KinematicsConfig {
    fn default() -> Self {
        KinematicsConfig {
            stall_threshold_ns: STALL_THRESHOLD_NS_DEFAULT,
            unit_mm: UNIT_MM,
            checksum_policy: ChecksumPolicy::Apply,
        }
    }
}

/// A [`KinematicsConfig`] that cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum KinematicsConfigError {
    /// A zero threshold would call every interval a stall.
    #[error("`stall_threshold_ns` is 0; expected a positive number of ns (default 10 ms)")]
    StallThresholdZero,
    /// The unit must be a positive, finite number of millimetres.
    #[error("`unit_mm` is {0}; expected a positive, finite number of mm per position unit (default 0.01)")]
    UnitNotPositive(f64),
}

impl KinematicsConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), KinematicsConfigError> {
        if self.stall_threshold_ns == 0 {
            return Err(KinematicsConfigError::StallThresholdZero);
        }
        if !(self.unit_mm.is_finite() && self.unit_mm > 0.0) {
            return Err(KinematicsConfigError::UnitNotPositive(self.unit_mm));
        }
        Ok(())
    }
}

/// The pose of one arm, relative to where the stream started.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ArmPose {
    /// Position `[x, y, z]`, position units.
    pub position: [i64; 3],
    /// Sum of the applied rotation increments `[Qx, Qy, Qz]`, frame units.
    pub rotation: [f64; 3],
    /// Last applied grasp command.
    pub grasp: i32,
}

/// Gaps between consecutive frames longer than the stall threshold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Stalls {
    /// Number of such gaps.
    pub count: u64,
    /// Sum of their whole lengths, ns.
    pub total_ns: u64,
    /// The longest, ns.
    pub longest_ns: u64,
}

impl Stalls {
    #[inline]
    fn observe(&mut self, gap_ns: u64, threshold_ns: u64) {
        if gap_ns > threshold_ns {
            self.count += 1;
            self.total_ns += gap_ns;
            self.longest_ns = self.longest_ns.max(gap_ns);
        }
    }
}

#[inline]
fn norm3(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Integrates one stream of frames.
#[derive(Debug, Clone)]
pub struct Integrator {
    config: KinematicsConfig,
    frames: u64,
    frames_applied: u64,
    frames_discarded: u64,
    checksum_mismatches: u64,
    poses: [ArmPose; ARMS],
    length_units: [f64; ARMS],
    clutch_engaged: Option<bool>,
    clutch_activations: u64,
    stalls: Stalls,
    last_ns: Option<u64>,
}

impl Integrator {
    /// An integrator at the origin that has seen no frame.
    pub fn new(config: KinematicsConfig) -> Result<Integrator, KinematicsConfigError> {
        config.validate()?;
        Ok(Integrator {
            config,
            frames: 0,
            frames_applied: 0,
            frames_discarded: 0,
            checksum_mismatches: 0,
            poses: [ArmPose::default(); ARMS],
            length_units: [0.0; ARMS],
            clutch_engaged: None,
            clutch_activations: 0,
            stalls: Stalls::default(),
            last_ns: None,
        })
    }

    /// Takes one frame at `time_ns`. Returns whether its commands applied
    /// (clutch engaged and not discarded for its checksum).
    pub fn push(&mut self, time_ns: u64, frame: &ItpFrame) -> bool {
        self.frames += 1;
        if !frame.has_valid_checksum() {
            self.checksum_mismatches += 1;
            if self.config.checksum_policy == ChecksumPolicy::Discard {
                self.frames_discarded += 1;
                return false;
            }
        }

        // Times may arrive out of order (frames are reordered before they are
        // received); a stall is a gap after the latest time seen so far.
        match self.last_ns {
            Some(last_ns) if time_ns > last_ns => {
                self.stalls.observe(time_ns - last_ns, self.config.stall_threshold_ns);
                self.last_ns = Some(time_ns);
            }
            Some(_) => {}
            None => self.last_ns = Some(time_ns),
        }

        // An engage edge needs a previous frame: the state before the first
        // frame is unknown, so the first frame never counts as one.
        let engaged = frame.clutch_engaged();
        if self.clutch_engaged == Some(false) && engaged {
            self.clutch_activations += 1;
        }
        self.clutch_engaged = Some(engaged);
        if !engaged {
            return false;
        }

        self.frames_applied += 1;
        for arm in 0..ARMS {
            let inc = frame.increment(arm);
            let pose = &mut self.poses[arm];
            for (p, d) in pose.position.iter_mut().zip(inc) {
                *p += d as i64;
            }
            let rot = frame.rotation(arm);
            for (r, d) in pose.rotation.iter_mut().zip(rot) {
                *r += d;
            }
            pose.grasp = frame.grasp[arm];
            self.length_units[arm] += norm3(inc.map(f64::from));
        }
        true
    }

    /// Ends the stream at `end_ns`: a gap from the last frame to `end_ns`
    /// longer than the threshold counts as a stall. Call at most once.
    pub fn close(&mut self, end_ns: u64) {
        if let Some(last_ns) = self.last_ns {
            if end_ns > last_ns {
                self.stalls.observe(end_ns - last_ns, self.config.stall_threshold_ns);
                self.last_ns = Some(end_ns);
            }
        }
    }

    /// The current pose of one arm.
    pub fn pose(&self, arm: usize) -> &ArmPose {
        &self.poses[arm]
    }

    /// Motion length of one arm so far: the sum of the lengths of its applied
    /// increments, position units.
    pub fn length_units(&self, arm: usize) -> f64 {
        self.length_units[arm]
    }

    /// Whether the clutch was engaged in the last frame taken.
    pub fn clutch_engaged(&self) -> Option<bool> {
        self.clutch_engaged
    }

    /// Everything measured so far.
    pub fn report(&self) -> SideReport {
        SideReport {
            frames: self.frames,
            frames_applied: self.frames_applied,
            frames_discarded: self.frames_discarded,
            checksum_mismatches: self.checksum_mismatches,
            clutch_activations: self.clutch_activations,
            length_units: self.length_units,
            length_mm: self.length_units.map(|l| l * self.config.unit_mm),
            poses: self.poses,
            stalls: self.stalls,
        }
    }
}

/// What one side (console or robot) measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SideReport {
    /// Frames taken.
    pub frames: u64,
    /// Frames whose commands applied (clutch engaged, not discarded).
    pub frames_applied: u64,
    /// Frames ignored because their checksum did not match
    /// ([`ChecksumPolicy::Discard`]).
    pub frames_discarded: u64,
    /// Frames whose checksum did not match, applied or not.
    pub checksum_mismatches: u64,
    /// Clutch engage edges (released → engaged between consecutive frames).
    pub clutch_activations: u64,
    /// Motion length per arm, position units.
    pub length_units: [f64; ARMS],
    /// Motion length per arm, mm.
    pub length_mm: [f64; ARMS],
    /// Final pose per arm.
    pub poses: [ArmPose; ARMS],
    /// Gaps between frames longer than the threshold.
    pub stalls: Stalls,
}

/// How far the robot's pose is from the console's, for one arm.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ArmDivergence {
    /// Position distance at the end, position units.
    pub final_units: f64,
    /// Position distance at the end, mm.
    pub final_mm: f64,
    /// Largest position distance seen, position units.
    pub max_units: f64,
    /// Largest position distance seen, mm.
    pub max_mm: f64,
    /// Distance between the summed rotation increments at the end, frame
    /// units.
    pub rotation_final: f64,
    /// Difference of the grasp commands at the end (robot − console).
    pub grasp_final: i64,
}

/// The full kinematic account of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct KinematicsReport {
    /// Millimetres per position unit used for the mm figures.
    pub unit_mm: f64,
    /// Every frame the console sent.
    pub console: SideReport,
    /// Every frame the robot received.
    pub robot: SideReport,
    /// Robot pose against console pose, per arm.
    pub divergence: [ArmDivergence; ARMS],
}

/// Console-side and robot-side integration of one run, and their divergence.
///
/// Feed both sides in time order. The largest divergence is sampled each time
/// the robot takes a frame (and at [`Kinematics::close`]), comparing it with
/// the console's pose at that moment: under delay it includes the lag, under
/// loss the increments that never arrived. The final divergence, once every
/// frame in flight has arrived, is what loss left for good.
#[derive(Debug, Clone)]
pub struct Kinematics {
    unit_mm: f64,
    console: Integrator,
    robot: Integrator,
    max_units: [f64; ARMS],
}

impl Kinematics {
    /// Both sides at the origin.
    pub fn new(config: KinematicsConfig) -> Result<Kinematics, KinematicsConfigError> {
        Ok(Kinematics {
            unit_mm: config.unit_mm,
            console: Integrator::new(config)?,
            robot: Integrator::new(config)?,
            max_units: [0.0; ARMS],
        })
    }

    /// A frame the console sent at `time_ns`.
    pub fn console(&mut self, time_ns: u64, frame: &ItpFrame) {
        self.console.push(time_ns, frame);
    }

    /// A frame the robot received at `time_ns`.
    pub fn robot(&mut self, time_ns: u64, frame: &ItpFrame) {
        self.robot.push(time_ns, frame);
        self.sample_divergence();
    }

    /// Ends both streams at `end_ns` (a trailing gap may be a stall) and takes
    /// a last divergence sample.
    pub fn close(&mut self, end_ns: u64) {
        self.console.close(end_ns);
        self.robot.close(end_ns);
        self.sample_divergence();
    }

    fn sample_divergence(&mut self) {
        for arm in 0..ARMS {
            self.max_units[arm] = self.max_units[arm].max(self.divergence_units(arm));
        }
    }

    /// Current position distance between robot and console for one arm,
    /// position units.
    pub fn divergence_units(&self, arm: usize) -> f64 {
        let (c, r) = (self.console.pose(arm), self.robot.pose(arm));
        norm3(core::array::from_fn(|k| (r.position[k] - c.position[k]) as f64))
    }

    /// The console side.
    pub fn console_side(&self) -> &Integrator {
        &self.console
    }

    /// The robot side.
    pub fn robot_side(&self) -> &Integrator {
        &self.robot
    }

    /// Everything measured so far.
    pub fn report(&self) -> KinematicsReport {
        let divergence = core::array::from_fn(|arm| {
            let (c, r) = (self.console.pose(arm), self.robot.pose(arm));
            let final_units = self.divergence_units(arm);
            ArmDivergence {
                final_units,
                final_mm: final_units * self.unit_mm,
                max_units: self.max_units[arm],
                max_mm: self.max_units[arm] * self.unit_mm,
                rotation_final: norm3(core::array::from_fn(|k| r.rotation[k] - c.rotation[k])),
                grasp_final: r.grasp as i64 - c.grasp as i64,
            }
        });
        KinematicsReport {
            unit_mm: self.unit_mm,
            console: self.console.report(),
            robot: self.robot.report(),
            divergence,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SURGEON_DISENGAGED, SURGEON_ENGAGED};

    const MS: u64 = 1_000_000;

    fn frame(sequence: u32, inc0: [i32; 3], inc1: [i32; 3], surgeon_mode: i32) -> ItpFrame {
        ItpFrame {
            sequence,
            delx: [inc0[0], inc1[0]],
            dely: [inc0[1], inc1[1]],
            delz: [inc0[2], inc1[2]],
            qw: [1.0, 1.0],
            grasp: [sequence as i32 * 10, -(sequence as i32)],
            surgeon_mode,
            ..ItpFrame::default()
        }
        .with_checksum()
    }

    fn kin() -> Kinematics {
        Kinematics::new(KinematicsConfig::default()).unwrap()
    }

    #[test]
    fn bad_config_is_rejected() {
        let c = KinematicsConfig { stall_threshold_ns: 0, ..KinematicsConfig::default() };
        assert_eq!(Kinematics::new(c).unwrap_err(), KinematicsConfigError::StallThresholdZero);
        for unit_mm in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let c = KinematicsConfig { unit_mm, ..KinematicsConfig::default() };
            assert!(matches!(Integrator::new(c), Err(KinematicsConfigError::UnitNotPositive(_))));
        }
    }

    #[test]
    fn motion_length_and_pose() {
        let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
        assert!(i.push(0, &frame(1, [3, 4, 0], [0, 0, -2], SURGEON_ENGAGED)));
        assert!(i.push(MS, &frame(2, [0, 0, 12], [1, 2, 2], SURGEON_ENGAGED)));
        let r = i.report();
        assert_eq!(r.length_units, [5.0 + 12.0, 2.0 + 3.0]);
        assert_eq!(r.length_mm, [0.17, 0.05]);
        assert_eq!(r.poses[0].position, [3, 4, 12]);
        assert_eq!(r.poses[1].position, [1, 2, 0]);
        assert_eq!(r.poses[0].grasp, 20);
        assert_eq!(r.frames_applied, 2);
    }

    #[test]
    fn released_clutch_freezes_the_arm_and_engage_edges_count() {
        let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
        let modes = [1, 1, 0, 0, 1, 0, 1, 1];
        for (k, &m) in modes.iter().enumerate() {
            i.push(k as u64 * MS, &frame(k as u32, [1, 0, 0], [0, 1, 0], m));
        }
        let r = i.report();
        assert_eq!(r.clutch_activations, 2);
        assert_eq!(r.frames_applied, 5);
        assert_eq!(r.poses[0].position, [5, 0, 0]);
        assert_eq!(r.poses[1].position, [0, 5, 0]);
        assert_eq!(r.length_units, [5.0, 5.0]);
        // The grasp of the last applied frame (sequence 7).
        assert_eq!(r.poses[0].grasp, 70);

        // A stream that starts released counts its first engagement.
        let mut j = Integrator::new(KinematicsConfig::default()).unwrap();
        j.push(0, &frame(0, [0; 3], [0; 3], SURGEON_DISENGAGED));
        j.push(MS, &frame(1, [0; 3], [0; 3], SURGEON_ENGAGED));
        assert_eq!(j.report().clutch_activations, 1);
    }

    #[test]
    fn rotation_increments_add_up() {
        let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
        let mut f = frame(0, [0; 3], [0; 3], SURGEON_ENGAGED);
        f.qx = [1.0, 0.0];
        f.qz = [-2.0, 0.5];
        i.push(0, &f);
        i.push(MS, &f);
        assert_eq!(i.pose(0).rotation, [2.0, 0.0, -4.0]);
        assert_eq!(i.pose(1).rotation, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn stalls_are_gaps_over_the_threshold() {
        let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
        let f = frame(0, [0; 3], [0; 3], SURGEON_ENGAGED);
        // Gaps: 5, 15, 1, 29, 10 (not over), then 3 back in time (ignored).
        for t_ms in [0, 5, 20, 21, 50, 60, 57] {
            i.push(t_ms * MS, &f);
        }
        assert_eq!(i.report().stalls, Stalls { count: 2, total_ns: 44 * MS, longest_ns: 29 * MS });
        // A trailing gap of 40 ms to the end of the run is a third.
        i.close(100 * MS);
        assert_eq!(i.report().stalls, Stalls { count: 3, total_ns: 84 * MS, longest_ns: 40 * MS });
    }

    #[test]
    fn checksum_mismatches_are_counted_and_optionally_discarded() {
        let mut bad = frame(5, [7, 0, 0], [0; 3], SURGEON_ENGAGED);
        bad.checksum ^= 1;
        let mut apply = Integrator::new(KinematicsConfig::default()).unwrap();
        assert!(apply.push(0, &bad));
        assert_eq!(apply.report().checksum_mismatches, 1);
        assert_eq!(apply.pose(0).position, [7, 0, 0]);

        let config = KinematicsConfig { checksum_policy: ChecksumPolicy::Discard, ..KinematicsConfig::default() };
        let mut discard = Integrator::new(config).unwrap();
        assert!(!discard.push(0, &bad));
        let r = discard.report();
        assert_eq!((r.checksum_mismatches, r.frames_discarded, r.frames_applied), (1, 1, 0));
        assert_eq!(r.poses[0].position, [0, 0, 0]);
    }

    #[test]
    fn one_lost_increment_is_exactly_the_divergence() {
        // Lockstep: the robot receives every frame but the third, whose arm-0
        // increment is (3, 4, 0): a divergence of exactly 5 units = 0.05 mm.
        let mut k = kin();
        for s in 0..10u32 {
            let inc0 = if s == 2 { [3, 4, 0] } else { [1, -1, 2] };
            let f = frame(s, inc0, [2, 2, 1], SURGEON_ENGAGED);
            let t = s as u64 * 2 * MS;
            k.console(t, &f);
            if s != 2 {
                k.robot(t + MS, &f);
            }
        }
        k.close(20 * MS);
        let r = k.report();
        assert_eq!(r.divergence[0].final_units, 5.0);
        assert_eq!(r.divergence[0].max_units, 5.0);
        assert!((r.divergence[0].final_mm - 0.05).abs() < 1e-12);
        assert_eq!(r.divergence[1].final_units, 3.0);
        assert_eq!(r.divergence[1].max_units, 3.0);
        // The robot's grasp follows the last frame, which arrived.
        assert_eq!(r.divergence[0].grasp_final, 0);
        assert_eq!(r.console.frames, 10);
        assert_eq!(r.robot.frames, 9);
        // 2·sqrt(6)·8 + ... on the console side; the robot lacks 5 and 3.
        assert!((r.console.length_units[0] - r.robot.length_units[0] - 5.0).abs() < 1e-9);
        assert!((r.console.length_units[1] - r.robot.length_units[1] - 3.0).abs() < 1e-9);
        // The lost frame leaves a 4 ms gap on the robot side: under 10 ms.
        assert_eq!(r.robot.stalls.count, 0);
    }

    #[test]
    fn lost_increment_during_released_clutch_costs_nothing() {
        let mut k = kin();
        let moving = frame(0, [100, 0, 0], [0; 3], SURGEON_DISENGAGED);
        k.console(0, &moving);
        let r = k.report();
        assert_eq!(r.divergence[0].final_units, 0.0);
        assert_eq!(r.console.poses[0].position, [0, 0, 0]);
    }

    #[test]
    fn delay_shows_as_lag_then_vanishes() {
        // Every frame arrives 3 frames late: while they are in flight the
        // robot trails by 3 increments of length 2; at the end it has caught
        // up.
        let mut k = kin();
        let f = |s| frame(s, [2, 0, 0], [0; 3], SURGEON_ENGAGED);
        for s in 0..10u32 {
            k.console(s as u64 * MS, &f(s));
            if s >= 3 {
                k.robot(s as u64 * MS, &f(s - 3));
            }
        }
        for s in 7..10u32 {
            k.robot((10 + s as u64) * MS, &f(s));
        }
        let r = k.report();
        // After the robot takes frame s−3 the console has sent s+1 frames.
        assert_eq!(r.divergence[0].max_units, 6.0);
        assert_eq!(r.divergence[0].final_units, 0.0);
    }
}
