//! ROS 2 topics as a transport: the emulator takes a topic's messages in
//! and writes them out on another, of any message type, relaying each
//! message's serialized bytes (CDR) as they are. DDS is spoken by RustDDS
//! (pure Rust, RTPS on UDP), so no ROS installation is needed; ROS 2's
//! conventions on the wire are kept (topic `rt/<name>`, type
//! `<pkg>::msg::dds_::<Type>_`).
//!
//! # Contract
//!
//! - One participant per emulator ([`Ros2Node`]), in one domain; every lane's
//!   readers and writers are its endpoints.
//! - A message is taken into a slot of netfi's own ([`Slots`], fixed at
//!   start-up) without being deserialized; what does not fit, is empty, or
//!   is in an encapsulation the emulator does not relay is said by its
//!   [`Payload`], never dropped unseen.
//! - The writer never blocks: a reliable send window that is full is a
//!   failed write ([`WriteFailure::WindowFull`]).
//! - The graph (who publishes and subscribes what, of which type, with which
//!   QoS; who left and why; who cannot match and why) is polled off the hot
//!   path ([`Ros2Node::poll`]).

pub mod args;
pub mod names;
pub mod node;
pub mod port;
pub mod qos;
pub mod senders;

pub use args::{Ros2Args, DEFAULT_MAX_BYTES};
pub use names::{NameError, TopicName, TypeName};
pub use node::{GraphEvent, Happened, OpenError, Remote, Role, Ros2Node};
pub use port::{unix_ns, OutBuffers, Payload, Reader, Slots, TakeError, Taken, WriteFailure, Writer};
