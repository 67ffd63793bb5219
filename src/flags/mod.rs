//! Command-line flags as values: the renderer that writes a group of flags
//! back as the argv that parses to it ([`argv`]), and the ranges and value
//! parsers every numeric flag is checked with where it is parsed
//! ([`values`]). A leaf: the flag groups of the services
//! (`crate::service::args`) and of the transports (`crate::transport`) both
//! build on it.

pub mod argv;
pub mod values;

pub use argv::{Argv, Render};
