//! The ROS 2 tools beside the emulator's ROS 2 lanes: `netfi ros2 record`
//! and `replay`, topics as MCAP (rosbag2's format).

pub mod bag;
