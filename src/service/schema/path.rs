//! What one path of the emulator reports: the account every link keeps
//! (and the rule that it closes), what the link measured, and the report
//! of a path, the same for every channel.

use crate::metrics::Summary;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// What a link did with the items that entered it:
/// `entered + duplicated = delivered + dropped + held_at_end`
/// (`duplicated` is 0 without `duplicate` stages). Each direction of the
/// emulator, and the streams summed, keep one.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Account {
    pub entered: u64,
    /// Released (including those whose send failed); copies included.
    pub delivered: u64,
    /// Copies made by `duplicate` stages (each then delivered, dropped or
    /// held like an item).
    #[serde(default)]
    pub duplicated: u64,
    /// Frames and copies queued with bits flipped by `corrupt` stages, and
    /// of those the ones delivered (counted by the trace writer: exact
    /// unless the trace overflowed).
    #[serde(default)]
    pub corrupted: u64,
    #[serde(default)]
    pub corrupted_delivered: u64,
    /// Dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
}

impl Account {
    /// Items dropped, all reasons.
    pub fn dropped_total(&self) -> u64 {
        self.dropped.values().sum()
    }

    /// Whether every item that entered (and every copy) is accounted for.
    pub fn closes(&self) -> bool {
        self.entered + self.duplicated == self.delivered + self.dropped_total() + self.held_at_end
    }

    /// Adds `o`'s counts to these.
    pub fn add(&mut self, o: &Account) {
        self.entered += o.entered;
        self.delivered += o.delivered;
        self.duplicated += o.duplicated;
        self.corrupted += o.corrupted;
        self.corrupted_delivered += o.corrupted_delivered;
        for (k, v) in &o.dropped {
            *self.dropped.entry(k.clone()).or_default() += v;
        }
        self.held_at_end += o.held_at_end;
    }
}

/// What a link measured: the loss it realized and the delays it injected,
/// and what it cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkMeasures {
    /// The scenario's drops over the frames it decided: a malformed frame
    /// (`wrong_size`, `bad_checksum`, `bad_flags`, `too_large`), dropped
    /// before the scenario, is in neither. The figure the models' loss
    /// compares with.
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    /// The models' loss in bursts longer than the run likely met
    /// (`check::unseen_loss_rate`), included in the upper end of
    /// `loss_rate_ci95`; absent where no stage has such bursts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_rate_unseen_model: Option<f64>,
    pub stages: Vec<crate::check::StageReport>,
    /// Injected delay of released items.
    pub injected_delay_ns: Summary,
    /// Sender's send → item taken in (the first hop plus any time the item
    /// waited in the port for the emulator).
    pub ingress_wait_ns: Summary,
    /// Item taken in → fate decided.
    pub decision_ns: Summary,
    /// Actual − scheduled release.
    pub release_lateness_ns: Summary,
    /// The link stages (`rate`, `trace`): utilisation, queue occupancy
    /// second by second, queueing delay percentiles, as `netfi scenario
    /// check` reports them (absent when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<crate::check::LinkReport>,
}

/// What one direction of the emulator did (a path's report), the same for
/// every channel; `extra` is what the channel adds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathReport<X> {
    pub scenario: String,
    pub seed: u64,
    pub queue_order: String,
    pub queue_capacity: usize,
    #[serde(flatten)]
    pub account: Account,
    /// Of the delivered, those released while no receiver was subscribed.
    pub delivered_unsubscribed: u64,
    /// The account closes, and the channel's own counts agree with it.
    pub balanced: bool,
    #[serde(flatten)]
    pub measures: LinkMeasures,
    pub send_errors: u64,
    pub receive_errors: u64,
    #[serde(default)]
    pub trace_overflowed: u64,
    pub trace_path: PathBuf,
    /// The decision-time and release-lateness histogram logs, where the
    /// path writes them (the forward stream).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hlogs: Option<(PathBuf, PathBuf)>,
    #[serde(flatten)]
    pub extra: X,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn account(entered: u64, delivered: u64, dropped: u64, held: u64) -> Account {
        Account { entered, delivered, dropped: [("bernoulli".to_string(), dropped)].into(), held_at_end: held, ..Account::default() }
    }

    #[test]
    fn an_account_closes_only_when_every_item_is_accounted_for() {
        assert!(account(10, 6, 3, 1).closes());
        assert!(!account(10, 6, 3, 0).closes());
        let mut copies = account(10, 8, 3, 1);
        assert!(!copies.closes());
        copies.duplicated = 2;
        assert!(copies.closes());
        let mut sum = account(10, 6, 3, 1);
        sum.add(&copies);
        assert_eq!((sum.entered, sum.delivered, sum.duplicated, sum.dropped_total(), sum.held_at_end), (20, 14, 2, 6, 2));
        assert!(sum.closes());
    }
}
