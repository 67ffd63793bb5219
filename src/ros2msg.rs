//! Known kinematic ROS 2 messages, read from their serialized bytes, and
//! the motion they describe on both sides of the emulator.
//!
//! Contract:
//!
//! - The bytes are a message's CDR body as ROS 2's middleware writes it
//!   (little endian, each primitive aligned to its size from the body's
//!   start; what follows the 4-byte encapsulation header).
//! - Three types: geometry_msgs/PoseStamped and TransformStamped (a
//!   position, m, and an orientation) and sensor_msgs/JointState (up to
//!   [`JOINTS_MAX`] joint positions). A message that ends before its type
//!   says, or whose lengths run past its end, is a [`DecodeError`], never a
//!   panic.
//! - Poses are absolute, not increments (unlike ITP): each message replaces
//!   the last, so a lost one costs the robot nothing once the next arrives.
//!   [`Motion`] follows the console's side (every message that entered) and
//!   the robot's (every message released): each side's motion length, the
//!   robot's stalls, and how far the robot's last pose is from the
//!   console's, sampled at each message of either side.
//! - Each known type's message definition, as ROS 2 bags keep it
//!   (encoding `ros2msg`: the type's `.msg` fields, then each type it uses,
//!   after a line of 80 `=` and `MSG: pkg/msg/Type`), for MCAP files that
//!   tools decode without the type installed.
//! - Pure: no clock (times come in as ns), no I/O, and nothing allocates.

use crate::kinematics::Stalls;
use serde::Serialize;

/// The most joints of a JointState followed.
pub const JOINTS_MAX: usize = 16;

/// The delimiter of a used type's definition, and that definition (the
/// pieces of [`Kind::definition`]).
macro_rules! msg_dependency {
    ($name:literal, $fields:literal) => {
        concat!("================================================================================\nMSG: ", $name, "\n", $fields)
    };
}
macro_rules! msg_header {
    () => {
        msg_dependency!("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id\n")
    };
}
macro_rules! msg_time {
    () => {
        msg_dependency!("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n")
    };
}
macro_rules! msg_pose {
    () => {
        msg_dependency!("geometry_msgs/msg/Pose", "Point position\nQuaternion orientation\n")
    };
}
macro_rules! msg_point {
    () => {
        msg_dependency!("geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z\n")
    };
}
macro_rules! msg_quaternion {
    () => {
        msg_dependency!("geometry_msgs/msg/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n")
    };
}
macro_rules! msg_transform {
    () => {
        msg_dependency!("geometry_msgs/msg/Transform", "Vector3 translation\nQuaternion rotation\n")
    };
}
macro_rules! msg_vector3 {
    () => {
        msg_dependency!("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z\n")
    };
}

/// A known kinematic message type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    PoseStamped,
    TransformStamped,
    JointState,
}

impl Kind {
    /// The kind of the ROS 2 type `pkg/msg/Type`, if known.
    pub fn of(ros_type: &str) -> Option<Kind> {
        match ros_type {
            "geometry_msgs/msg/PoseStamped" => Some(Kind::PoseStamped),
            "geometry_msgs/msg/TransformStamped" => Some(Kind::TransformStamped),
            "sensor_msgs/msg/JointState" => Some(Kind::JointState),
            _ => None,
        }
    }

    /// Its complete message definition in ROS 2's `ros2msg` form: its own
    /// fields first, then every type it uses (transitively), each after
    /// the two-line delimiter. The fields are those of the ROS 2 `.msg`
    /// files (Kilted), without their comments.
    pub fn definition(self) -> &'static str {
        match self {
            Kind::PoseStamped => concat!("std_msgs/Header header\nPose pose\n", msg_header!(), msg_pose!(), msg_point!(), msg_quaternion!(), msg_time!()),
            Kind::TransformStamped => {
                concat!("std_msgs/Header header\nstring child_frame_id\nTransform transform\n", msg_header!(), msg_transform!(), msg_vector3!(), msg_quaternion!(), msg_time!())
            }
            Kind::JointState => concat!("std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n", msg_header!(), msg_time!()),
        }
    }

    /// The unit of its coordinates, for the report.
    pub fn unit(self) -> &'static str {
        match self {
            Kind::PoseStamped | Kind::TransformStamped => "m",
            Kind::JointState => "joint units (rad or m)",
        }
    }
}

/// A message that is not what its type says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// It ends before a field at this byte.
    #[error("the message ends at byte {len}, before its field at byte {at}")]
    Truncated { at: usize, len: usize },
    /// A string or sequence length at this byte runs past its end.
    #[error("a length of {count} at byte {at} runs past the message's {len} bytes")]
    Length { count: u32, at: usize, len: usize },
    /// More joints than are followed.
    #[error("{0} joints, more than the {JOINTS_MAX} followed")]
    TooManyJoints(u32),
}

/// What a message says of where the arm is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Its header's stamp, ns.
    pub stamp_ns: i64,
    /// Coordinates: a pose's position (3) and orientation quaternion
    /// (x, y, z, w); a joint state's positions.
    pub q: [f64; JOINTS_MAX],
    /// How many of `q` are positions (3 for a pose).
    pub positions: usize,
}

/// A reader of CDR, little endian.
struct Cdr<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Cdr<'a> {
    fn align(&mut self, n: usize) {
        self.at = self.at.div_ceil(n) * n;
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        self.align(n.min(8));
        let end = self.at.checked_add(n).filter(|e| *e <= self.b.len()).ok_or(DecodeError::Truncated { at: self.at, len: self.b.len() })?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }

    fn f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().expect("8 bytes")))
    }

    /// A count at the current position that must fit in what is left, at
    /// `size` bytes an element.
    fn count(&mut self, size: usize) -> Result<u32, DecodeError> {
        let at = self.at;
        let n = self.u32()?;
        let room = self.b.len().saturating_sub(self.at);
        if (n as usize).saturating_mul(size) > room {
            return Err(DecodeError::Length { count: n, at, len: self.b.len() });
        }
        Ok(n)
    }

    fn skip_string(&mut self) -> Result<(), DecodeError> {
        let n = self.count(1)?;
        self.at += n as usize;
        Ok(())
    }

    /// A header: its stamp, ns.
    fn header(&mut self) -> Result<i64, DecodeError> {
        let sec = self.u32()? as i32;
        let nanosec = self.u32()?;
        self.skip_string()?;
        Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
    }
}

/// Reads a `kind` message from its CDR body.
pub fn decode(kind: Kind, bytes: &[u8]) -> Result<Sample, DecodeError> {
    let mut c = Cdr { b: bytes, at: 0 };
    let stamp_ns = c.header()?;
    let mut q = [0.0; JOINTS_MAX];
    let positions = match kind {
        Kind::PoseStamped | Kind::TransformStamped => {
            if kind == Kind::TransformStamped {
                c.skip_string()?;
            }
            for v in q.iter_mut().take(7) {
                *v = c.f64()?;
            }
            3
        }
        Kind::JointState => {
            let names = c.count(4)?;
            for _ in 0..names {
                c.skip_string()?;
            }
            let n = c.count(8)?;
            if n as usize > JOINTS_MAX {
                return Err(DecodeError::TooManyJoints(n));
            }
            for v in q.iter_mut().take(n as usize) {
                *v = c.f64()?;
            }
            n as usize
        }
    };
    Ok(Sample { stamp_ns, q, positions })
}

/// One side's motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Side {
    messages: u64,
    last: Option<Sample>,
    length: f64,
    last_ns: Option<u64>,
    stalls: Stalls,
}

impl Side {
    fn push(&mut self, t_ns: u64, s: &Sample, stall_threshold_ns: u64) {
        if let Some(l) = &self.last {
            self.length += distance(l, s);
        }
        if let Some(t) = self.last_ns {
            let gap = t_ns.saturating_sub(t);
            if gap > stall_threshold_ns {
                self.stalls.count += 1;
                self.stalls.total_ns += gap;
                self.stalls.longest_ns = self.stalls.longest_ns.max(gap);
            }
        }
        self.messages += 1;
        self.last = Some(*s);
        self.last_ns = Some(t_ns);
    }

    fn report(&self) -> SideMotion {
        SideMotion { messages: self.messages, length: self.length, stalls: self.stalls }
    }
}

/// The distance between two samples' positions (of the joints both have).
fn distance(a: &Sample, b: &Sample) -> f64 {
    let n = a.positions.min(b.positions);
    a.q[..n].iter().zip(&b.q[..n]).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// The console's and the robot's motion, and how far apart they are.
#[derive(Debug, Clone)]
pub struct Motion {
    kind: Kind,
    stall_threshold_ns: u64,
    console: Side,
    robot: Side,
    divergence_max: f64,
    divergence_sum: f64,
    divergence_samples: u64,
    /// Messages that did not read as their type.
    pub malformed: u64,
    /// The last such message's error.
    pub last_error: Option<DecodeError>,
}

/// One side of [`MotionReport`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SideMotion {
    pub messages: u64,
    /// The path its positions trace, in the kind's unit.
    pub length: f64,
    /// Gaps between its messages longer than the threshold.
    pub stalls: Stalls,
}

/// What [`Motion`] measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MotionReport {
    pub kind: Kind,
    pub unit: &'static str,
    pub stall_threshold_ns: u64,
    /// Every message that entered the emulator, in order.
    pub console: SideMotion,
    /// Every message released, in order.
    pub robot: SideMotion,
    /// The distance between the robot's last position and the console's,
    /// sampled at each message of either side once both have one: the
    /// largest, the mean, and at the end.
    pub divergence_max: f64,
    pub divergence_mean: Option<f64>,
    pub divergence_final: Option<f64>,
    pub malformed: u64,
    pub last_error: Option<String>,
}

impl Motion {
    /// Follows `kind` messages; a gap longer than `stall_threshold_ns`
    /// between two robot messages is a stall.
    pub fn new(kind: Kind, stall_threshold_ns: u64) -> Motion {
        Motion {
            kind,
            stall_threshold_ns,
            console: Side::default(),
            robot: Side::default(),
            divergence_max: 0.0,
            divergence_sum: 0.0,
            divergence_samples: 0,
            malformed: 0,
            last_error: None,
        }
    }

    /// The kind followed.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// Reads `bytes`; counts it if it is malformed.
    #[inline]
    pub fn read(&mut self, bytes: &[u8]) -> Option<Sample> {
        match decode(self.kind, bytes) {
            Ok(s) => Some(s),
            Err(e) => {
                self.malformed += 1;
                self.last_error = Some(e);
                None
            }
        }
    }

    /// A message entered at `t_ns`.
    #[inline]
    pub fn console(&mut self, t_ns: u64, s: &Sample) {
        self.console.push(t_ns, s, self.stall_threshold_ns);
        self.diverge();
    }

    /// A message was released at `t_ns`.
    #[inline]
    pub fn robot(&mut self, t_ns: u64, s: &Sample) {
        self.robot.push(t_ns, s, self.stall_threshold_ns);
        self.diverge();
    }

    #[inline]
    fn diverge(&mut self) {
        if let (Some(c), Some(r)) = (&self.console.last, &self.robot.last) {
            let d = distance(c, r);
            self.divergence_max = self.divergence_max.max(d);
            self.divergence_sum += d;
            self.divergence_samples += 1;
        }
    }

    /// What it measured.
    pub fn report(&self) -> MotionReport {
        let final_d = match (&self.console.last, &self.robot.last) {
            (Some(c), Some(r)) => Some(distance(c, r)),
            _ => None,
        };
        MotionReport {
            kind: self.kind,
            unit: self.kind.unit(),
            stall_threshold_ns: self.stall_threshold_ns,
            console: self.console.report(),
            robot: self.robot.report(),
            divergence_max: self.divergence_max,
            divergence_mean: (self.divergence_samples > 0).then(|| self.divergence_sum / self.divergence_samples as f64),
            divergence_final: final_d,
            malformed: self.malformed,
            last_error: self.last_error.map(|e| e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
    }

    // Serialized by rclpy (rclpy.serialization.serialize_message), less the
    // 4-byte encapsulation header: a PoseStamped stamped 1 s 2 ns in frame
    // `ab` at x = 1.5, w = 1; a TransformStamped in `w` to `tool` at y = 2.
    const POSE: &str = "01000000020000000300000061620000000000000000f83f00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000f03f";
    const TRANSFORM: &str = "0000000000000000020000007700000005000000746f6f6c0000000000000000000000000000000000000000000000400000000000000000000000000000000000000000000000000000000000000000000000000000f03f";

    /// A JointState as its CDR: stamp, empty frame id, `names`, `positions`.
    fn joint_state(names: &[&str], positions: &[f64]) -> Vec<u8> {
        let mut b = Vec::new();
        let align = |b: &mut Vec<u8>, n: usize| b.resize(b.len().div_ceil(n) * n, 0);
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        b.extend_from_slice(&1u32.to_le_bytes());
        b.push(0);
        align(&mut b, 4);
        b.extend_from_slice(&(names.len() as u32).to_le_bytes());
        for n in names {
            align(&mut b, 4);
            b.extend_from_slice(&(n.len() as u32 + 1).to_le_bytes());
            b.extend_from_slice(n.as_bytes());
            b.push(0);
        }
        align(&mut b, 4);
        b.extend_from_slice(&(positions.len() as u32).to_le_bytes());
        for p in positions {
            align(&mut b, 8);
            b.extend_from_slice(&p.to_le_bytes());
        }
        b
    }

    #[test]
    fn poses_and_transforms_read_as_rclpy_wrote_them() {
        let p = decode(Kind::PoseStamped, &hex(POSE)).unwrap();
        assert_eq!((p.stamp_ns, p.positions), (1_000_000_002, 3));
        assert_eq!(&p.q[..7], &[1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let t = decode(Kind::TransformStamped, &hex(TRANSFORM)).unwrap();
        assert_eq!(&t.q[..7], &[0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        assert_eq!(Kind::of("geometry_msgs/msg/PoseStamped"), Some(Kind::PoseStamped));
        assert_eq!(Kind::of("std_msgs/msg/String"), None);
    }

    #[test]
    fn each_definition_names_every_type_it_uses_once_after_the_delimiter() {
        let delimiter = format!("{}\nMSG: ", "=".repeat(80));
        for k in [Kind::PoseStamped, Kind::TransformStamped, Kind::JointState] {
            let parts: Vec<&str> = k.definition().split(&delimiter).collect();
            assert!(!parts[0].is_empty() && !parts[0].contains("MSG:"), "{k:?}: its own fields first");
            let defined: Vec<&str> = parts[1..].iter().map(|p| p.lines().next().unwrap()).collect();
            // Every complex field type (pkg/Type or a bare Type of the
            // same package) is defined once.
            let mut used = std::collections::BTreeSet::new();
            for (i, part) in parts.iter().enumerate() {
                let fields = if i == 0 { part } else { part.split_once('\n').unwrap().1 };
                for line in fields.lines() {
                    let ty = line.split(' ').next().unwrap().trim_end_matches("[]");
                    if ty.chars().next().is_some_and(char::is_uppercase) || ty.contains('/') {
                        used.insert(ty.rsplit('/').next().unwrap().to_string());
                    }
                }
            }
            let mut names: Vec<String> = defined.iter().map(|d| d.rsplit('/').next().unwrap().to_string()).collect();
            names.sort();
            assert_eq!(names, used.into_iter().collect::<Vec<_>>(), "{k:?}");
            assert!(defined.iter().all(|d| d.split('/').nth(1) == Some("msg")), "{defined:?}");
        }
    }

    #[test]
    fn joint_states_read_their_positions() {
        let b = joint_state(&["j1", "joint_2"], &[0.5, -1.25]);
        let s = decode(Kind::JointState, &b).unwrap();
        assert_eq!((s.stamp_ns, s.positions, s.q[0], s.q[1]), (3_000_000_000, 2, 0.5, -1.25));
        let many: Vec<f64> = (0..JOINTS_MAX + 1).map(|i| i as f64).collect();
        assert_eq!(decode(Kind::JointState, &joint_state(&[], &many)), Err(DecodeError::TooManyJoints(JOINTS_MAX as u32 + 1)));
    }

    #[test]
    fn malformed_messages_are_errors_at_every_length_never_panics() {
        let pose = hex(POSE);
        for n in 0..pose.len() {
            assert!(decode(Kind::PoseStamped, &pose[..n]).is_err(), "{n} bytes");
        }
        let js = joint_state(&["a"], &[1.0]);
        for n in 0..js.len() {
            assert!(decode(Kind::JointState, &js[..n]).is_err(), "{n} bytes");
        }
        // A string length that runs past the end.
        let mut bad = pose.clone();
        bad[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(decode(Kind::PoseStamped, &bad), Err(DecodeError::Length { count: u32::MAX, at: 8, .. })));
        // Garbage of every kind and length decodes or fails, never panics.
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for len in 0..300 {
            let g: Vec<u8> = (0..len)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            for k in [Kind::PoseStamped, Kind::TransformStamped, Kind::JointState] {
                let _ = decode(k, &g);
            }
        }
    }

    fn at(x: f64) -> Sample {
        let mut q = [0.0; JOINTS_MAX];
        q[0] = x;
        Sample { stamp_ns: 0, q, positions: 3 }
    }

    #[test]
    fn motion_measures_each_sides_path_the_robots_stalls_and_the_divergence() {
        let mut m = Motion::new(Kind::PoseStamped, 10_000_000);
        // The console moves 0 → 3 in steps of 1 every 1 ms; the robot gets
        // 0 and 3 (1 and 2 lost), 20 ms apart: a stall.
        for i in 0..4u64 {
            m.console(i * 1_000_000, &at(i as f64));
            if i == 0 {
                m.robot(500_000, &at(0.0));
            }
        }
        m.robot(20_500_000, &at(3.0));
        let r = m.report();
        assert_eq!((r.console.messages, r.console.length), (4, 3.0));
        assert_eq!((r.robot.messages, r.robot.length), (2, 3.0));
        assert_eq!((r.robot.stalls.count, r.robot.stalls.longest_ns), (1, 20_000_000));
        assert_eq!(r.divergence_max, 3.0);
        assert_eq!(r.divergence_final, Some(0.0));
        // Samples: robot at 0 (0), console at 1, 2, 3 (1, 2, 3), robot at 3 (0).
        assert_eq!(r.divergence_mean, Some(6.0 / 5.0));
    }
}
