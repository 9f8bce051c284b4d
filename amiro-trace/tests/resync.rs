//! The reader against damaged streams: garbage in front, records cut short, bytes dropped.
use amiro_trace::{records, Kind, Reader, Record, EVENT_LEN, MAX_WIRE};
use proptest::prelude::*;

fn kind() -> impl Strategy<Value = Kind> {
    prop_oneof![
        any::<u32>().prop_map(|clock_hz| Kind::Hello { clock_hz }),
        any::<u8>().prop_map(|task| Kind::TaskStart { task }),
        (any::<u8>(), any::<u32>()).prop_map(|(task, next_release_in_us)| Kind::TaskEnd {
            task,
            next_release_in_us
        }),
        prop::array::uniform18(any::<u8>()).prop_map(|record| Kind::Event { record }),
        any::<u16>().prop_map(|id| Kind::FrameAcked { id }),
        any::<u32>().prop_map(|count| Kind::Lost { count }),
    ]
}

fn record() -> impl Strategy<Value = Record> {
    (any::<u64>(), kind()).prop_map(|(cycles, kind)| Record { cycles, kind })
}

fn wire(list: &[Record]) -> Vec<u8> {
    list.iter()
        .flat_map(|r| r.encode().as_bytes().to_vec())
        .collect()
}

#[test]
fn a_known_record_on_the_wire() {
    let r = Record {
        cycles: 0x0102,
        kind: Kind::TaskStart { task: 3 },
    };
    let bytes = r.encode();
    // Body: 0x21, 02 01 00 00 00 00 00 00, 03, check; COBS code bytes replace the zeros.
    assert_eq!(&bytes.as_bytes()[..4], &[4, 0x21, 0x02, 0x01]);
    assert_eq!(*bytes.as_bytes().last().unwrap(), 0);
    assert!(!bytes.as_bytes()[..bytes.as_bytes().len() - 1].contains(&0));
    assert_eq!(records(bytes.as_bytes()).collect::<Vec<_>>(), vec![r]);
    assert_eq!(EVENT_LEN, 18);
}

#[test]
fn another_version_or_a_flipped_bit_is_skipped() {
    let r = Record {
        cycles: 77,
        kind: Kind::FrameAcked { id: 0x605 },
    };
    let good = r.encode().as_bytes().to_vec();
    for i in 0..good.len() - 1 {
        for bit in 0..8 {
            let mut bad = good.clone();
            bad[i] ^= 1 << bit;
            let mut reader = Reader::new();
            let out: Vec<Record> = bad.iter().filter_map(|&b| reader.push(b)).collect();
            assert!(
                out.is_empty() || out == [r] && bad == good,
                "byte {i} bit {bit}"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn round_trip(list in prop::collection::vec(record(), 0..40)) {
        prop_assert_eq!(records(&wire(&list)).collect::<Vec<_>>(), list);
    }

    #[test]
    fn any_garbage_in_front_loses_nothing_after_the_first_delimiter(
        garbage in prop::collection::vec(any::<u8>(), 0..300),
        list in prop::collection::vec(record(), 1..20),
    ) {
        let mut bytes = garbage.clone();
        bytes.push(0); // the garbage ends where the first record's delimiter-free run begins
        bytes.extend(wire(&list));
        let got: Vec<Record> = records(&bytes).collect();
        // Garbage can never make a record appear that was not sent, beyond what it
        // itself happens to spell; every sent record is read, in order, at the end.
        prop_assert!(got.ends_with(&list));
    }

    #[test]
    fn garbage_without_a_delimiter_costs_at_most_the_first_record(
        garbage in prop::collection::vec(1u8..=255, 0..300),
        list in prop::collection::vec(record(), 1..20),
    ) {
        let mut bytes = garbage;
        bytes.extend(wire(&list));
        let got: Vec<Record> = records(&bytes).collect();
        prop_assert!(got.ends_with(&list[1..]));
        prop_assert!(got.len() <= list.len());
    }

    #[test]
    fn a_cut_record_costs_itself_and_at_most_its_successor(
        list in prop::collection::vec(record(), 3..20),
        which in any::<prop::sample::Index>(),
        keep in any::<prop::sample::Index>(),
    ) {
        let k = which.index(list.len());
        let mut bytes = Vec::new();
        for (i, r) in list.iter().enumerate() {
            let w = r.encode();
            let w = w.as_bytes();
            if i == k {
                // Cut: the writer stopped somewhere inside the record (delimiter lost too).
                bytes.extend(&w[..keep.index(w.len())]);
            } else {
                bytes.extend(w);
            }
        }
        let got: Vec<Record> = records(&bytes).collect();
        let mut expected: Vec<Record> = list[..k].to_vec();
        let after: Vec<Record> = list[(k + 2).min(list.len())..].to_vec();
        prop_assert!(got.starts_with(&expected));
        prop_assert!(got.ends_with(&after));
        prop_assert!(got.len() < list.len());
        expected.extend(after);
        prop_assert!(got.len() >= expected.len());
    }

    #[test]
    fn dropped_bytes_lose_only_the_records_they_hit(
        list in prop::collection::vec(record(), 1..30),
        drops in prop::collection::vec(any::<prop::sample::Index>(), 1..6),
    ) {
        let mut owner = Vec::new();
        let mut bytes = Vec::new();
        for (i, r) in list.iter().enumerate() {
            for &b in r.encode().as_bytes() {
                owner.push(i);
                bytes.push(b);
            }
        }
        let dropped: std::collections::BTreeSet<usize> =
            drops.iter().map(|d| d.index(bytes.len())).collect();
        let hit: std::collections::BTreeSet<usize> = dropped.iter().map(|&i| owner[i]).collect();
        let kept: Vec<u8> = bytes
            .iter()
            .enumerate()
            .filter(|(i, _)| !dropped.contains(i))
            .map(|(_, &b)| b)
            .collect();
        let got: Vec<Record> = records(&kept).collect();
        // A record no dropped byte touched, whose predecessor kept its delimiter, is read intact.
        for (i, r) in list.iter().enumerate() {
            let predecessor_whole = i == 0 || !hit.contains(&(i - 1));
            if !hit.contains(&i) && predecessor_whole {
                prop_assert!(got.contains(r), "record {} lost", i);
            }
        }
        // Nothing is read that was not sent.
        for r in &got {
            prop_assert!(list.contains(r));
        }
    }

    #[test]
    fn random_bytes_never_panic_and_stay_bounded(bytes in prop::collection::vec(any::<u8>(), 0..4000)) {
        let mut reader = Reader::new();
        for b in bytes {
            let _ = reader.push(b);
        }
        prop_assert!(reader.stats().records <= 4000 / 11);
        prop_assert!(MAX_WIRE < 64);
    }
}
