//! The Python benchmark's flags.

use crate::common::args::{Common, Cores};
use serde::Serialize;
use std::path::PathBuf;

/// `cargo bench --bench python -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "python", bin_name = "cargo bench --bench python --", about = "What the netfi emulator adds between Python processes, over iceoryx2 and the UDP bridge")]
pub struct Args {
    #[command(flatten)]
    pub common: Common,
    #[command(flatten)]
    pub cores: Cores,
    /// The netfi binary whose emulator is measured [default: this
    /// package's build]
    #[arg(long, value_name = "PATH")]
    pub netfi: Option<PathBuf>,
    /// Parts to run
    #[arg(long, value_delimiter = ',', default_value = "iceoryx2,udp", value_parser = ["iceoryx2", "udp"])]
    pub parts: Vec<String>,
    /// Length of each part after a 0.5 s warm-up
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Frames a second on each route
    #[arg(long, default_value_t = 1000.0)]
    pub rate_hz: f64,
    /// Length of the windows the host is sampled in
    #[arg(long, default_value_t = 1.0)]
    pub window_s: f64,
    /// A quiet window's largest steal fraction
    #[arg(long, default_value_t = 0.01)]
    pub quiet_steal: f64,
    /// … and, for a calm one, the most cores other processes keep busy
    #[arg(long, default_value_t = 0.25)]
    pub quiet_others: f64,
    /// The interpreter
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Run the Python console and robot at this nice value (e.g. -10, with
    /// root: ahead of other work on their core)
    #[arg(long, allow_hyphen_values = true)]
    pub python_nice: Option<i32>,
}
