//! What a shared flag means to one command, where that differs from the
//! group's own help (given with clap's `mut_arg`).

/// `netfi emulator`'s help of `--streams` and `--stream-scenario`.
pub const EMULATOR_STREAMS: [&str; 2] = [
    "Serve this many console → robot streams in one loop (iceoryx2 on both sides): stream K's services are those of run `<run-id>-s<K>` (stream 0: the run's own), its files go to `<out>/stream-K/`",
    "Stream K's scenario (file or preset), as `K=SCENARIO`; repeatable. Streams not named take --scenario",
];

/// `netfi emulator`'s help of `--scenario`.
pub const EMULATOR_SCENARIO: &str = "A scenario file or preset name";

/// `netfi emulator`'s help of `--return-scenario` and `--return-seed`.
pub const EMULATOR_RETURN: [&str; 2] = [
    "Pass what comes back from the robot side through this scenario (file or preset): the robot's feedback with iceoryx2 on both sides (default Normal: nothing injected), datagrams with UDP on both sides (default: relayed untouched)",
    "Seed of the return scenario (default: the file's, else derived from --seed; printed)",
];

/// `netfi run`'s help of `--seed`.
pub const RUN_SEED: &str =
    "Seed of the run: the scenario's random streams, the synthetic motion and, derived from it, each stream's and each return path's (default: the scenario file's, else random; printed)";

/// `netfi run`'s help of its placement flags: `--emulator-core`, `--no-pin`, `--isolate`.
pub const RUN_PLACEMENT: [&str; 3] = [
    "Core for the emulator (default: the last core)",
    "Do not pin the emulator (its core is then neither its own nor cleared)",
    "Clear the emulator's core for the run (the default): move other processes' threads, movable kernel threads (e.g. a VM's memory monitor) and device interrupts off it, and put them back at the end (root or CAP_SYS_NICE for other users' threads)",
];

/// `netfi run`'s help of `--no-feedback`.
pub const RUN_NO_FEEDBACK: &str =
    "Run without the feedback path: the robot's feedback is not carried back to the console (no round trip, no feedback section in the report)";
