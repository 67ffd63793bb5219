use super::*;
use crate::scenario::parse_str;

fn injector(text: &str, capacity: usize) -> Injector<u32> {
    Injector::new(Scenario::new(&parse_str(text, "s.toml", "s").unwrap(), 9).unwrap(), capacity)
}

#[test]
fn copies_keep_the_books_balanced() {
    let mut inj = injector(
        "[[stage]]\nmodel = \"duplicate\"\np = 0.3\n[[stage]]\nmodel = \"bernoulli\"\np = 0.2\n[[stage]]\nmodel = \"delay\"\nmin_ms = 3\n",
        1 << 12,
    );
    let mut copies = 0u64;
    let mut released_per_index = std::collections::BTreeMap::<u64, u32>::new();
    for i in 0..20_000u64 {
        let t = i * 1_000_000;
        while let Some(r) = inj.pop_due(t) {
            *released_per_index.entry(r.ingress_index).or_default() += 1;
            assert_eq!(r.item, r.ingress_index as u32, "a copy carries its original's item");
        }
        let e = inj.ingress(t, i as u32);
        copies += u64::from(e.copies);
        let c = inj.counts();
        assert!(c.balanced(), "{c:?}");
    }
    while let Some(r) = inj.pop_due(u64::MAX) {
        *released_per_index.entry(r.ingress_index).or_default() += 1;
    }
    let c = inj.counts();
    assert!(c.balanced() && c.held == 0, "{c:?}");
    assert!(c.duplicated > 5_000 && copies > 4_000 && copies < c.duplicated, "{c:?} {copies}");
    assert_eq!(c.released, c.entered + c.duplicated - c.dropped());
    assert!(released_per_index.values().all(|&n| n <= 2));
    assert_eq!(released_per_index.values().map(|&n| u64::from(n)).sum::<u64>(), c.released);
}

#[test]
fn a_copy_that_does_not_fit_is_queue_full() {
    let mut inj = injector("[[stage]]\nmodel = \"duplicate\"\np = 1\n[[stage]]\nmodel = \"delay\"\nmin_ms = 1\n", 1);
    let e = inj.ingress(0, 7);
    assert!(matches!(e.fate, Fate::Scheduled { .. }));
    assert_eq!(e.copies, 0);
    let c = inj.counts();
    assert_eq!((c.duplicated, c.dropped_queue_full, c.held), (1, 1, 1));
    assert!(c.balanced());
}

#[test]
fn the_caller_applies_the_flips_to_its_own_bytes() {
    let text = "[[stage]]\nmodel = \"corrupt\"\np = 0.5\n[[stage]]\nmodel = \"duplicate\"\np = 0.5\n";
    let sc = Scenario::new(&parse_str(text, "s.toml", "s").unwrap(), 3).unwrap();
    // The queue's items need `Default`, which a 124-byte array lacks.
    #[derive(Clone, Copy, PartialEq, Debug)]
    struct Bytes([u8; 124]);
    impl Default for Bytes {
        fn default() -> Self {
            Bytes([0; 124])
        }
    }
    let mut inj: Injector<Bytes> = Injector::new(sc, 1 << 10);
    let clean = Bytes(crate::frame::ItpFrame { sequence: 7, delx: [3, -1], qw: [1.0, 1.0], surgeon_mode: 1, ..Default::default() }.with_checksum().to_bytes());
    let (mut corrupted_seen, mut released) = (0u64, 0u64);
    for i in 0..2_000u64 {
        let e = inj.ingress_with(i, clean, |b, flips| crate::frame::flip_bits(&mut b.0, flips.bits()));
        assert_eq!(e.corrupted, matches!(e.fate, Fate::Scheduled { .. }) && e.corrupted);
        while let Some(r) = inj.pop_due(u64::MAX) {
            released += 1;
            let differing: u32 = r.item.0.iter().zip(&clean.0).map(|(a, b)| (a ^ b).count_ones()).sum();
            assert!(differing <= 1, "one corrupt stage flips at most one bit");
            corrupted_seen += u64::from(differing == 1);
        }
    }
    let c = inj.counts();
    assert_eq!(c.corrupted, corrupted_seen);
    assert_eq!(c.released, released);
    assert!(c.balanced() && corrupted_seen > 800, "{c:?}");
    // `ingress` leaves the item as it is.
    let mut plain: Injector<Bytes> =
        Injector::new(Scenario::new(&parse_str("[[stage]]\nmodel = \"corrupt\"\np = 1\n", "s.toml", "s").unwrap(), 3).unwrap(), 4);
    assert!(plain.ingress(0, clean).corrupted);
    assert_eq!(plain.pop_due(0).unwrap().item, clean);
}

#[test]
fn without_duplication_the_old_balance_holds() {
    let mut inj = injector("[[stage]]\nmodel = \"bernoulli\"\np = 0.5\n", 16);
    for i in 0..100 {
        inj.ingress(i, 0);
        while inj.pop_due(i).is_some() {}
    }
    let c = inj.counts();
    assert_eq!(c.duplicated, 0);
    assert_eq!(c.entered, c.released + c.dropped() + c.held);
}
