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
mod tests;
