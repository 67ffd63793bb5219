//! What the forward stream adds to its path's report (the `extra` of
//! [`super::PathReport`]); each reverse channel declares its own beside it
//! (`crate::service::channel`).

use super::BadInput;
use serde::{Deserialize, Serialize};

/// What the forward channel adds to its path's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ForwardExtra {
    pub sent_by_console: Option<u64>,
    pub bad_checksum_passed: u64,
    pub bad_input: BadInput,
    /// The motion in the frames taken in and released, when followed
    /// (`--kinematics`); carried into `emulator.json` by the lane's report.
    #[serde(skip)]
    pub kinematics: Option<crate::kinematics::KinematicsReport>,
}
