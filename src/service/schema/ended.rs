//! Why a process's stream or loop ended (`ended_by` in `console.json`,
//! `simulator.json`, `emulator.json` and the run report): one type that
//! the process writing a report and every reader of it share, so the
//! words on disk are named once.
//!
//! A value this build does not know (a file from a newer netfi, or edited
//! by hand) is refused with the file, the line and the accepted words:
//! a report that reads as something else than what was written would be
//! worse than none. Every word any version of netfi has written is here.

use core::fmt;
use serde::{Deserialize, Serialize};

/// How a stream or a loop ended. The serialized word is the snake_case
/// name (`end_marker`, `peer_died`, …), and so is its [`fmt::Display`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ended {
    /// The sender's end marker came, and everything held was released
    /// (the emulator, the robot, the console's feedback).
    EndMarker,
    /// A stop was requested: SIGINT, SIGTERM, or iceoryx2's termination
    /// request.
    Signal,
    /// The emulator found a peer of the run dead (its `dead_peers` say
    /// which) and ended once the rest had drained.
    PeerDied,
    /// The console sent every frame it was to send.
    Done,
    /// The console stopped early because the emulator ended the feedback
    /// (its robot was gone).
    EmulatorEnded,
    /// The console's feedback: nobody published feedback.
    NoEmulator,
    /// The console's feedback: no end marker within `--feedback-wait-s`.
    Timeout,
}

impl Ended {
    /// Every value, in the order above.
    pub const ALL: [Ended; 7] = [Ended::EndMarker, Ended::Signal, Ended::PeerDied, Ended::Done, Ended::EmulatorEnded, Ended::NoEmulator, Ended::Timeout];

    /// The word written in the reports.
    pub const fn as_str(self) -> &'static str {
        match self {
            Ended::EndMarker => "end_marker",
            Ended::Signal => "signal",
            Ended::PeerDied => "peer_died",
            Ended::Done => "done",
            Ended::EmulatorEnded => "emulator_ended",
            Ended::NoEmulator => "no_emulator",
            Ended::Timeout => "timeout",
        }
    }
}

impl fmt::Display for Ended {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_value_is_written_as_its_word_and_read_back() {
        for e in Ended::ALL {
            let json = serde_json::to_string(&e).unwrap();
            assert_eq!(json, format!("\"{}\"", e.as_str()));
            assert_eq!(e.to_string(), e.as_str());
            assert_eq!(serde_json::from_str::<Ended>(&json).unwrap(), e);
        }
        let words: Vec<&str> = Ended::ALL.iter().map(|e| e.as_str()).collect();
        assert_eq!(words, ["end_marker", "signal", "peer_died", "done", "emulator_ended", "no_emulator", "timeout"]);
    }

    #[test]
    fn an_unknown_word_is_refused_naming_it_and_the_accepted_ones() {
        let e = serde_json::from_str::<Ended>("\"robot_left\"").unwrap_err().to_string();
        assert!(e.contains("robot_left") && e.contains("end_marker") && e.contains("timeout"), "{e}");
    }
}
