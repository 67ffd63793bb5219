//! The QoS of the emulator's ROS 2 endpoints: taken from the publisher it
//! relays (so whatever that publisher's subscribers accept, the relay's
//! writer offers), or given on the command line; checked against the
//! endpoints they must match by DDS's request/offer rules, so a pair that
//! cannot match is an error that names the policy, never a silent absence
//! of messages.

use rustdds::policy::{Durability, History, Reliability};
use rustdds::{Duration, QosPolicies, QosPolicyBuilder};
use serde::{Deserialize, Serialize};

/// The history the emulator's readers keep at least, messages: the DDS
/// reader's buffer between its receive thread and the emulator's loop. The
/// loop takes each message as it comes; what a burst beyond this
/// overwrites is counted from the writer's sequence numbers
/// (`lost_before_ingress`).
pub const READER_DEPTH_MIN: i32 = 1024;

/// The QoS a ROS 2 topic's subscribers get without asking (rclpy's and
/// rclcpp's default profile): reliable, volatile, the last 10.
pub fn ros_default() -> QosPolicies {
    QosPolicyBuilder::new().reliability(Reliability::Reliable { max_blocking_time: Duration::ZERO }).durability(Durability::Volatile).history(History::KeepLast { depth: 10 }).build()
}

/// A QoS given on the command line that is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("QoS `{text}`: `{token}` is not a policy (give a comma-separated list of `reliable` or `best_effort`, `volatile` or `transient_local`, `depth=N` or `keep_all`)")]
pub struct QosParseError {
    /// The QoS given.
    pub text: String,
    /// The part of it that is not a policy.
    pub token: String,
}

/// Reads `reliable,transient_local,depth=10` (any subset, any order) over
/// `base`.
pub fn parse(text: &str, base: &QosPolicies) -> Result<QosPolicies, QosParseError> {
    let mut b = QosPolicyBuilder::new();
    for token in text.split(',').map(str::trim).filter(|t| !t.is_empty()) {
        b = match token {
            "reliable" => b.reliability(Reliability::Reliable { max_blocking_time: Duration::ZERO }),
            "best_effort" => b.reliability(Reliability::BestEffort),
            "volatile" => b.durability(Durability::Volatile),
            "transient_local" => b.durability(Durability::TransientLocal),
            "keep_all" => b.history(History::KeepAll),
            t => match t.strip_prefix("depth=").and_then(|d| d.parse::<i32>().ok()).filter(|d| *d >= 1) {
                Some(depth) => b.history(History::KeepLast { depth }),
                None => return Err(QosParseError { text: text.to_string(), token: t.to_string() }),
            },
        };
    }
    Ok(base.modify_by(&b.build()))
}

/// What several publishers of one topic all offer: the least reliability
/// and durability among them and the deepest history, so that one reader
/// asking for it matches each. `None` for no publisher.
pub fn weakest<'a>(offered: impl IntoIterator<Item = &'a QosPolicies>) -> Option<QosPolicies> {
    offered.into_iter().fold(None, |acc: Option<QosPolicies>, q| {
        let Some(a) = acc else { return Some(q.clone()) };
        let reliability = a.reliability().unwrap_or(Reliability::BestEffort).min(q.reliability().unwrap_or(Reliability::BestEffort));
        let durability = a.durability().unwrap_or(Durability::Volatile).min(q.durability().unwrap_or(Durability::Volatile));
        let history = a.history().unwrap_or(History::KeepLast { depth: 1 }).max(q.history().unwrap_or(History::KeepLast { depth: 1 }));
        Some(a.modify_by(&QosPolicyBuilder::new().reliability(reliability).durability(durability).history(history).build()))
    })
}

/// What the emulator's reader of a topic asks for, to receive what
/// `offered` publishes: its reliability and durability (a reader that asks
/// for no more than is offered always matches), and a history deep enough
/// for the loop ([`READER_DEPTH_MIN`]).
pub fn reader(offered: &QosPolicies) -> QosPolicies {
    let depth = match offered.history() {
        Some(History::KeepLast { depth }) => depth.max(READER_DEPTH_MIN),
        _ => READER_DEPTH_MIN,
    };
    let b = QosPolicyBuilder::new()
        .reliability(offered.reliability().unwrap_or(Reliability::BestEffort))
        .durability(offered.durability().unwrap_or(Durability::Volatile))
        .history(History::KeepLast { depth });
    b.build()
}

/// What the emulator's writer offers by default: what the publishers
/// offered (`offered`; ROS 2's default without one), with a history of
/// [`READER_DEPTH_MIN`]: discovery does not announce a publisher's history,
/// and a reliable writer keeps what it may have to resend there, so a
/// shallow one would lose a burst of releases (a delay stage releasing
/// what it held).
pub fn relay(offered: Option<&QosPolicies>) -> QosPolicies {
    let base = offered.cloned().unwrap_or_else(ros_default);
    base.modify_by(&QosPolicyBuilder::new().history(History::KeepLast { depth: READER_DEPTH_MIN }).build())
}

/// What the emulator's writer offers: `wanted`, except that a reliable
/// write never blocks the loop (a full send window is a failed release,
/// counted).
pub fn writer(wanted: &QosPolicies) -> QosPolicies {
    match wanted.reliability() {
        Some(Reliability::Reliable { .. }) => wanted.modify_by(&QosPolicyBuilder::new().reliability(Reliability::Reliable { max_blocking_time: Duration::ZERO }).build()),
        _ => wanted.clone(),
    }
}

/// The QoS profiles `offered` as rosbag2 writes them in an MCAP channel's
/// `offered_qos_profiles` metadata: a YAML list, one profile a publisher,
/// each policy by its number in `rmw_qos_profile_t`. Discovery does not
/// announce a publisher's history, so it is `3` (unknown) with depth 0, as
/// rosbag2 records a remote publisher; an infinite duration is
/// `RMW_DURATION_INFINITE`.
pub fn rosbag2_profiles<'a>(offered: impl IntoIterator<Item = &'a QosPolicies>) -> String {
    use rustdds::policy::Liveliness;
    let time = |d: Option<Duration>| match d.filter(|d| *d != Duration::INFINITE) {
        Some(d) => {
            let ns = d.to_nanoseconds().max(0);
            (ns / 1_000_000_000, ns % 1_000_000_000)
        }
        None => (9_223_372_036, 854_775_807),
    };
    let mut yaml = String::new();
    for q in offered {
        let reliability = match q.reliability() {
            Some(Reliability::BestEffort) => 2,
            _ => 1,
        };
        let durability = match q.durability() {
            Some(Durability::TransientLocal | Durability::Transient | Durability::Persistent) => 1,
            _ => 2,
        };
        let (liveliness, lease) = match q.liveliness() {
            Some(Liveliness::ManualByTopic { lease_duration }) => (3, Some(lease_duration)),
            Some(Liveliness::Automatic { lease_duration } | Liveliness::ManualByParticipant { lease_duration }) => (1, Some(lease_duration)),
            None => (1, None),
        };
        let times: String = [("deadline", q.deadline().map(|d| d.0)), ("lifespan", q.lifespan().map(|l| l.duration)), ("liveliness_lease_duration", lease)]
            .into_iter()
            .map(|(key, d)| {
                let (sec, nsec) = time(d);
                format!("  {key}:\n    sec: {sec}\n    nsec: {nsec}\n")
            })
            .collect();
        yaml.push_str(&format!("- history: 3\n  depth: 0\n  reliability: {reliability}\n  durability: {durability}\n  liveliness: {liveliness}\n{times}  avoid_ros_namespace_conventions: false\n"));
    }
    if yaml.is_empty() {
        yaml.push_str("[]\n");
    }
    yaml
}

/// Why an offered and a requested QoS cannot match.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{policy}: {writer} offers {offered}, {reader} requests {requested}; DDS matches a writer with a reader only when the offer is at least the request")]
pub struct QosMismatch {
    /// The policy (`reliability`, `durability`, `deadline`, …).
    pub policy: &'static str,
    /// Who offers (the writer), as named by the caller.
    pub writer: String,
    /// Who requests (the reader), as named by the caller.
    pub reader: String,
    /// What the writer offers.
    pub offered: String,
    /// What the reader requests.
    pub requested: String,
}

/// Whether a writer offering `offered` (named `writer`) can match a reader
/// requesting `requested` (named `reader`).
pub fn check(offered: &QosPolicies, requested: &QosPolicies, writer: &str, reader: &str) -> Result<(), QosMismatch> {
    let Some(id) = offered.compliance_failure_wrt(requested) else { return Ok(()) };
    let (o, r) = (Summary::of(offered), Summary::of(requested));
    let (policy, offered, requested) = match format!("{id:?}").as_str() {
        "Reliability" => ("reliability", o.reliability, r.reliability),
        "Durability" => ("durability", o.durability, r.durability),
        "Deadline" => ("deadline", fmt_ms(o.deadline_ms), fmt_ms(r.deadline_ms)),
        "Liveliness" => ("liveliness", o.liveliness, r.liveliness),
        other => (policy_name(other), format!("{offered:?}"), format!("{requested:?}")),
    };
    Err(QosMismatch { policy, writer: writer.to_string(), reader: reader.to_string(), offered, requested })
}

fn policy_name(debug: &str) -> &'static str {
    match debug {
        "Presentation" => "presentation",
        "LatencyBudget" => "latency budget",
        "Ownership" => "ownership",
        "DestinationOrder" => "destination order",
        "DataRepresentation" => "data representation",
        _ => "a QoS policy",
    }
}

fn fmt_ms(ms: Option<f64>) -> String {
    ms.map_or("no deadline".to_string(), |ms| format!("a deadline of {ms} ms"))
}

/// A QoS as the report and the messages give it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `reliable` or `best_effort`.
    pub reliability: String,
    /// `volatile`, `transient_local`, `transient` or `persistent`.
    pub durability: String,
    /// `keep_last` or `keep_all`.
    pub history: String,
    /// The depth of `keep_last`.
    pub depth: Option<i32>,
    /// The deadline, `None`: none.
    pub deadline_ms: Option<f64>,
    /// The lifespan, `None`: infinite.
    pub lifespan_ms: Option<f64>,
    /// `automatic`, `manual_by_participant` or `manual_by_topic`, with its
    /// lease.
    pub liveliness: String,
}

/// A DDS duration in ms, `None` when infinite.
fn ms(d: Duration) -> Option<f64> {
    (d != Duration::INFINITE).then(|| d.to_nanoseconds() as f64 / 1e6)
}

impl Summary {
    /// `q`, with DDS's defaults for what it leaves out.
    pub fn of(q: &QosPolicies) -> Summary {
        let reliability = match q.reliability() {
            Some(Reliability::Reliable { .. }) => "reliable",
            _ => "best_effort",
        };
        let durability = match q.durability().unwrap_or(Durability::Volatile) {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient_local",
            Durability::Transient => "transient",
            Durability::Persistent => "persistent",
        };
        let (history, depth) = match q.history().unwrap_or(History::KeepLast { depth: 1 }) {
            History::KeepLast { depth } => ("keep_last", Some(depth)),
            History::KeepAll => ("keep_all", None),
        };
        let liveliness = match q.liveliness() {
            None => "automatic".to_string(),
            Some(l) => {
                let kind = match l {
                    rustdds::policy::Liveliness::Automatic { .. } => "automatic",
                    rustdds::policy::Liveliness::ManualByParticipant { .. } => "manual_by_participant",
                    rustdds::policy::Liveliness::ManualByTopic { .. } => "manual_by_topic",
                };
                match ms(l.duration()) {
                    Some(lease) => format!("{kind}, lease {lease} ms"),
                    None => kind.to_string(),
                }
            }
        };
        Summary {
            reliability: reliability.to_string(),
            durability: durability.to_string(),
            history: history.to_string(),
            depth,
            deadline_ms: q.deadline().and_then(|d| ms(d.0)),
            lifespan_ms: q.lifespan().and_then(|l| ms(l.duration)),
            liveliness,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(text: &str) -> QosPolicies {
        parse(text, &ros_default()).unwrap()
    }

    #[test]
    fn the_command_line_form_reads_over_the_default() {
        let s = Summary::of(&q("best_effort,transient_local,depth=3"));
        assert_eq!((s.reliability.as_str(), s.durability.as_str(), s.history.as_str(), s.depth), ("best_effort", "transient_local", "keep_last", Some(3)));
        let s = Summary::of(&q(""));
        assert_eq!((s.reliability.as_str(), s.durability.as_str(), s.depth), ("reliable", "volatile", Some(10)));
        assert_eq!(Summary::of(&q("keep_all")).history, "keep_all");
        for bad in ["fast", "depth=0", "depth=x", "reliable,,lossy"] {
            let e = parse(bad, &ros_default()).unwrap_err();
            assert!(e.to_string().contains("is not a policy"), "{e}");
        }
    }

    #[test]
    fn a_reader_mirrors_what_is_offered_and_so_always_matches() {
        for offered in ["reliable", "best_effort", "transient_local", "best_effort,transient_local,depth=1"] {
            let offered = q(offered);
            let r = reader(&offered);
            assert_eq!(check(&offered, &r, "w", "r"), Ok(()));
            assert!(matches!(r.history(), Some(History::KeepLast { depth }) if depth >= READER_DEPTH_MIN));
        }
    }

    #[test]
    fn mismatches_name_the_policy_and_both_sides() {
        let e = check(&q("best_effort"), &q("reliable"), "the publisher /talker", "this lane's reader").unwrap_err();
        assert_eq!((e.policy, e.offered.as_str(), e.requested.as_str()), ("reliability", "best_effort", "reliable"));
        let text = e.to_string();
        assert!(text.contains("/talker") && text.contains("lane's reader"), "{text}");
        let e = check(&q("volatile"), &q("transient_local"), "w", "r").unwrap_err();
        assert_eq!(e.policy, "durability");
        // More than asked is fine.
        assert_eq!(check(&q("reliable,transient_local"), &q("best_effort,volatile"), "w", "r"), Ok(()));
    }

    #[test]
    fn one_reader_matches_every_publisher_of_a_topic() {
        let pubs = [q("reliable,transient_local,depth=5"), q("best_effort,volatile,depth=1")];
        let w = weakest(&pubs).unwrap();
        let r = reader(&w);
        for p in &pubs {
            assert_eq!(check(p, &r, "w", "r"), Ok(()));
        }
        assert_eq!(Summary::of(&w).depth, Some(5));
        assert!(weakest(&[]).is_none());
    }

    #[test]
    fn a_reliable_writer_never_blocks() {
        let w = writer(&q("reliable"));
        assert_eq!(w.reliability(), Some(Reliability::Reliable { max_blocking_time: Duration::ZERO }));
    }
}
