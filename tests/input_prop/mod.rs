//! Property-based tests of hostile input: the scenario parser
//! (`netfi::scenario::parse_str`) and the emulator's datagram classifier
//! (`netfi::service::emulator::classify`).
//!
//! - Random and mutated TOML never panics the parser, nor the validation of
//!   what it accepts (`Scenario::new`); every error names the line it is
//!   about, except the few that concern the file as a whole.
//! - Random bytes of any length, as the UDP source stores them in a
//!   sample, never panic the classifier and always get exactly the class
//!   the rule gives: the wrong length is `wrong_size`; a good checksum is
//!   a frame to decide; a bad one is `bad_checksum` or passed, as asked.
//!
//! Each property runs 1,000 cases by default (4,000 in all, a few seconds);
//! set `PROPTEST_CASES` for a longer run, as in the README.

use netfi::frame::ItpView;
use netfi::injector::Invalid;
use netfi::sample::{FrameSample, ITP_FRAME_LEN};
use netfi::scenario::{parse_str, Scenario};
use netfi::service::emulator::{classify, BadInput};
use proptest::prelude::*;

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    ProptestConfig { cases, failure_persistence: None, ..ProptestConfig::default() }
}

/// The example scenarios: the seeds of the mutations.
const SEEDS: [&str; 5] = [
    include_str!("../../config/scenarios/gilbert_elliott.toml"),
    include_str!("../../config/scenarios/jitter_fifo.toml"),
    include_str!("../../config/scenarios/netem_markov4.toml"),
    include_str!("../../config/scenarios/outage_timeline.toml"),
    include_str!("../../config/scenarios/plm2_dlm2.toml"),
];

/// Errors about the file as a whole, which have no one line to name.
const WHOLE_FILE: [&str; 2] = ["give exactly one of", "a timeline needs at least one"];

/// One edit of a scenario's text.
#[derive(Debug, Clone)]
enum Edit {
    /// Replace the bytes at `at..at+len` with `with`.
    Splice { at: usize, len: usize, with: String },
    /// Replace the `n`-th number in the text with `value`.
    Number { n: usize, value: String },
    /// Repeat line `n`.
    DuplicateLine { n: usize },
    /// Remove line `n`.
    DeleteLine { n: usize },
}

fn edit() -> impl Strategy<Value = Edit> {
    let tokens = prop::sample::select(vec![
        "=", "[", "]", "[[stage]]", "[[phase]]", "[[phase.stage]]", "\"", "'", "#", "\n", ",", "{", "}", "model = \"ge_lomax\"",
        "preset = \"PLM-2\"", "start_s = 1", "queue_capacity = 0", "seed = -1", "p = 2.0", "nan", "inf", "-0", "1e400",
        "\u{0}", "é", "\t",
    ]);
    let numbers = prop::sample::select(vec![
        "0", "-1", "1e308", "-1e308", "1e-320", "nan", "inf", "-inf", "18446744073709551616", "4294967296", "0.5", "1.0000001",
        "\"x\"", "[]", "[1, 2]", "true", "{}",
    ]);
    prop_oneof![
        (any::<usize>(), 0usize..8, prop_oneof![tokens.prop_map(String::from), "[ -~]{0,8}"])
            .prop_map(|(at, len, with)| Edit::Splice { at, len, with }),
        (any::<usize>(), numbers.prop_map(String::from)).prop_map(|(n, value)| Edit::Number { n, value }),
        any::<usize>().prop_map(|n| Edit::DuplicateLine { n }),
        any::<usize>().prop_map(|n| Edit::DeleteLine { n }),
    ]
}

fn apply(text: &str, e: &Edit) -> String {
    match e {
        Edit::Splice { at, len, with } => {
            let b = text.as_bytes();
            let at = at % (b.len() + 1);
            let end = (at + len).min(b.len());
            let mut v = b[..at].to_vec();
            v.extend_from_slice(with.as_bytes());
            v.extend_from_slice(&b[end..]);
            String::from_utf8_lossy(&v).into_owned()
        }
        Edit::Number { n, value } => {
            let spans: Vec<(usize, usize)> = number_spans(text);
            if spans.is_empty() {
                return text.to_string();
            }
            let (s, e) = spans[n % spans.len()];
            format!("{}{}{}", &text[..s], value, &text[e..])
        }
        Edit::DuplicateLine { n } | Edit::DeleteLine { n } => {
            let mut lines: Vec<&str> = text.lines().collect();
            if lines.is_empty() {
                return text.to_string();
            }
            let i = n % lines.len();
            if matches!(e, Edit::DuplicateLine { .. }) {
                lines.insert(i, lines[i]);
            } else {
                lines.remove(i);
            }
            lines.join("\n")
        }
    }
}

/// Byte spans of the numbers after a `=` (values, not keys).
fn number_spans(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if (b[i].is_ascii_digit() || b[i] == b'-') && i > 0 && matches!(b[i - 1], b' ' | b'=' | b'[' | b',') {
            let s = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || matches!(b[i], b'.' | b'-' | b'+' | b'_')) {
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

/// Parses `text`; an error must name a line within the text (or be about
/// the whole file); an accepted scenario must build or be refused cleanly.
fn check_parse(text: &str) -> Result<(), TestCaseError> {
    match parse_str(text, "<prop>", "prop") {
        Ok(spec) => {
            let _ = Scenario::new(&spec, 1);
        }
        Err(e) => {
            let whole = WHOLE_FILE.iter().any(|w| e.problem.contains(w));
            match e.line {
                Some(line) => {
                    let lines = text.lines().count().max(1);
                    prop_assert!(line >= 1 && line <= lines + 1, "line {} of a {}-line text: {}", line, lines, e);
                }
                None => prop_assert!(whole, "an error without a line: {}\n--- text ---\n{}", e, text),
            }
            // The message renders.
            let _ = e.to_string();
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mutated_scenarios_never_panic_and_errors_carry_a_line(
        seed in 0usize..SEEDS.len(),
        edits in prop::collection::vec(edit(), 1..6),
    ) {
        let mut text = SEEDS[seed].to_string();
        for e in &edits {
            text = apply(&text, e);
        }
        check_parse(&text)?;
    }

    #[test]
    fn random_text_never_panics_the_parser(text in "(\\PC|\n){0,200}") {
        check_parse(&text)?;
    }

    #[test]
    fn random_datagrams_are_classified_by_the_rule(
        bytes in prop::collection::vec(any::<u8>(), 0..300),
        drop_bad in any::<bool>(),
        good_checksum in any::<bool>(),
    ) {
        // As the UDP source stores a datagram: its first 124 bytes, the rest
        // zero, and its real length.
        let mut s = FrameSample::ZERO;
        let n = bytes.len().min(ITP_FRAME_LEN);
        s.wire[..n].copy_from_slice(&bytes[..n]);
        s.len = bytes.len() as u32;
        if good_checksum && bytes.len() == ITP_FRAME_LEN {
            let f = netfi::frame::ItpFrame::parse_unverified(&ItpView::new_unchecked(&s.wire[..])).with_checksum();
            s.wire = f.to_bytes();
        }
        let got = classify(&s, drop_bad, false, &mut BadInput::default());
        if bytes.len() != ITP_FRAME_LEN {
            prop_assert_eq!(got, Err((Invalid::WrongSize, None)));
        } else {
            let view = ItpView::new_unchecked(&s.wire[..]);
            let (seq, ok) = (view.sequence(), view.verify_checksum());
            let want = if ok { Ok((seq, false)) } else if drop_bad { Err((Invalid::BadChecksum, Some(seq))) } else { Ok((seq, true)) };
            prop_assert_eq!(got, want);
        }
    }

    #[test]
    fn raw_datagrams_are_always_passed(console_index in any::<u64>(), len in any::<u32>(), drop_bad in any::<bool>()) {
        let mut s = FrameSample::ZERO;
        s.flags = FrameSample::FLAG_RAW;
        s.len = len;
        s.console_index = console_index;
        prop_assert_eq!(classify(&s, drop_bad, true, &mut BadInput::default()), Ok((console_index as u32, false)));
    }
}
