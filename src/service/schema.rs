//! The JSON contracts between the processes of a run: what the emulator
//! writes (`emulator.json`, each path's section, `udp.json`) and the run
//! report (`report.json`) that joins it with the console's and the robot's.
//! Types only, and the rules that are part of a contract (an account
//! closes, a report finds its paths, the forward frames balance); no
//! process writes or reads a file here.
//!
//! | file | what |
//! |---|---|
//! | `ended` | why a process's stream or loop ended (`ended_by`) |
//! | `path` | the account every link keeps, what it measured, a path's report |
//! | `paths` | what each direction adds to its path's report |
//! | `emulator` | `emulator.json`: the shaping, the process, the reverse paths; several streams |
//! | `ros2` | `ros2.json`, and what the ROS 2 channels add to their paths' reports |
//! | `run` | `report.json`: the run report (`service::report` assembles it) |
//!
//! The console's and the robot's own reports (`console.json`,
//! `simulator.json`) stand beside their services.

pub mod emulator;
pub mod ended;
pub mod path;
pub mod paths;
pub mod ros2;
pub mod run;

pub use emulator::{BadInput, EmulatorFrames, EmulatorProcess, EmulatorReport, EmulatorStream, EmulatorStreams, LoopBusy, PeerEvent, Shaping, WithPaths};
pub use ended::Ended;
pub use path::{Account, LinkMeasures, PathReport};
pub use paths::ForwardExtra;
