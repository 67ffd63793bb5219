//! `rate` and `slot`: netem's own bottleneck and its slotting.

use super::{tc_field, time_us, TC_S32_MAX};
use anyhow::{bail, Result};

/// Bytes netem counts of an ITP frame's datagram beyond its payload: UDP
/// (8), IPv4 (20) and Ethernet (14) headers.
const NETEM_HEADER_BYTES: i64 = 42;

/// `rate` as netem's `rate … [packet_overhead [cellsize [celloverhead]]]`:
/// the text, the note, and the queue limit in packets.
pub(super) fn rate_as_netem(p: &netfi::model::RateParams, label: &str) -> Result<(String, String, u64)> {
    let m = netfi::model::Rate::new(p).map_err(|e| anyhow::anyhow!("{label}: {e}"))?;
    let packets = m.packets();
    let overhead = packets.overhead_bytes as i64 - NETEM_HEADER_BYTES;
    let mut text = format!("rate {}bit", m.rate_bit_s());
    let (cell, cell_overhead) = m.cell().unwrap_or((0, 0));
    if overhead != 0 || cell != 0 {
        text.push_str(&format!(" {overhead}"));
    }
    if cell != 0 {
        text.push_str(&format!(" {cell} {cell_overhead}"));
    }
    let mut notes = vec![format!(
        "packet_overhead {overhead}: netem counts the UDP/IPv4/Ethernet headers ({NETEM_HEADER_BYTES} bytes) netfi leaves out of the payload"
    )];
    let per_frame = packets.count(packets.payload_bytes);
    if per_frame > 1 {
        notes.push(format!("approximated: netfi cuts each {}-byte payload into {per_frame} packets sharing its fate; netem sends each datagram as it comes", packets.payload_bytes));
    }
    let limit = match packets.limit {
        netfi::model::backlog::QueueLimit::Packets(n) => n,
        netfi::model::backlog::QueueLimit::Bytes(b) => {
            let n = (b / packets.largest_packet_bytes()).max(1);
            notes.push(format!("approximated: netem's limit counts packets: queue_bytes {b} becomes {n} packets of this stage's size"));
            n
        }
    };
    Ok((text, format!("rate (netem's own): {}", notes.join("; ")), limit))
}


/// `slot` as netem's `slot MIN MAX [packets N] [bytes B]`, noting how
/// exact it is; refused where tc's signed 32-bit budgets cannot hold it.
pub(super) fn slot_line(p: &netfi::model::SlotParams, label: &str, notes: &mut Vec<String>) -> Result<String> {
    let mut text = format!("slot {} {}", time_us(p.min_ms.get()), time_us(p.max_ms.get()));
    if let Some(n) = p.packets {
        tc_field(label, "packets", n, TC_S32_MAX)?;
        text.push_str(&format!(" packets {n}"));
    }
    if let Some(b) = p.bytes {
        let scaled = (b as f64 * 166.0 / 124.0).ceil();
        if scaled > TC_S32_MAX as f64 {
            bail!(
                "{label}: `bytes` {b}: netem counts 166 bytes per frame where netfi counts 124, so it becomes {scaled:.0}, beyond tc's signed 32-bit field (netem takes 0 to {TC_S32_MAX}); at most {} here",
                (TC_S32_MAX as f64 * 124.0 / 166.0).floor()
            );
        }
        text.push_str(&format!(" bytes {}", scaled as u64));
        notes.push(format!("{label}: approximated: bytes scaled by 166/124 (netem counts the UDP/IPv4/Ethernet headers too)"));
    } else {
        notes.push(format!("{label}: exact (slot)"));
    }
    Ok(text)
}

