//! The bus model against schedules worked out by hand (one bit = 1 µs at 1 Mbit/s).
use super::*;

fn frame(id: u16, payload: &[u8]) -> Frame {
    Frame::new(id, payload).unwrap()
}

fn sent(events: &[Event]) -> Vec<(u16, NodeId, u64, u64)> {
    events
        .iter()
        .filter_map(|e| match *e {
            Event::Sent {
                frame,
                node,
                start,
                end,
                ..
            } => Some((frame.id, node, start, end)),
            _ => None,
        })
        .collect()
}

#[test]
fn frame_lengths_worked_by_hand() {
    // Identifier 0, no data: SOF … DLC are 19 dominant bits, the CRC of zeros is zero, so 34 zeros
    // carry 6 stuff bits (after the 5th, 10th, … 30th); + 10 tail bits = 50.
    assert_eq!(frame_bits(&frame(0, &[])), 50);
    // Every frame lies between the unstuffed length and the worst-case stuffing of Davis et al.
    for id in [0x000u16, 0x205, 0x605, 0x7FF, 0x2AA, 0x555] {
        for len in 0..=8usize {
            let payload: Vec<u8> = (0..len as u8)
                .map(|k| k.wrapping_mul(37) ^ id as u8)
                .collect();
            let bits = frame_bits(&frame(id, &payload));
            let stuffable = STUFFABLE_BITS + 8 * len as u32;
            assert!(bits >= stuffable + TAIL_BITS, "{id:#x}/{len}: {bits}");
            assert!(
                bits <= stuffable + TAIL_BITS + (stuffable - 1) / 4,
                "{id:#x}/{len}: {bits}"
            );
        }
    }
    assert!(Frame::new(0x800, &[]).is_none());
    assert!(Frame::new(1, &[0; 9]).is_none());
}

#[test]
fn arbitration_by_identifier_among_nodes_and_mailboxes() {
    let mut bus = Bus::new();
    let (a, b, c) = (bus.add_node(), bus.add_node(), bus.add_node());
    bus.queue(a, 0, frame(0x300, &[1]), 0).unwrap();
    bus.queue(a, 1, frame(0x100, &[2]), 0).unwrap();
    bus.queue(b, 0, frame(0x200, &[3]), 0).unwrap();
    // Queued while 0x100 is on the bus: too late for that arbitration, first in the next.
    bus.queue(c, 0, frame(0x050, &[4]), 10).unwrap();
    assert_eq!(
        bus.queue(a, 0, frame(0x010, &[]), 0),
        Err(QueueError::Occupied)
    );
    let events = bus.run_until(10_000);
    let l = |id, d| u64::from(frame_bits(&frame(id, &[d])));
    let s1 = 0;
    let s2 = s1 + l(0x100, 2) + 3;
    let s3 = s2 + l(0x050, 4) + 3;
    let s4 = s3 + l(0x200, 3) + 3;
    assert_eq!(
        sent(&events),
        vec![
            (0x100, a, s1, s1 + l(0x100, 2)),
            (0x050, c, s2, s2 + l(0x050, 4)),
            (0x200, b, s3, s3 + l(0x200, 3)),
            (0x300, a, s4, s4 + l(0x300, 1)),
        ]
    );
    let Event::Sent { receivers, .. } = events[0] else {
        panic!("{events:?}")
    };
    assert_eq!(receivers, 1 << b | 1 << c);
    assert_eq!(bus.idle_from(), s4 + l(0x300, 1) + 3);
}

#[test]
fn run_until_stops_before_a_start_at_the_limit() {
    let mut bus = Bus::new();
    let (a, _b) = (bus.add_node(), bus.add_node());
    bus.queue(a, 0, frame(0, &[]), 100).unwrap();
    assert!(bus.run_until(100).is_empty());
    // Starts on an idle bus the moment it is queued; 50 bits long.
    assert_eq!(sent(&bus.run_until(101)), vec![(0, a, 100, 150)]);
    // The next frame may start after the intermission only.
    bus.queue(a, 1, frame(0, &[]), 120).unwrap();
    assert_eq!(sent(&bus.run_until(1000)), vec![(0, a, 153, 203)]);
}

#[test]
fn a_bit_error_costs_an_error_frame_and_a_retransmission() {
    let mut bus = Bus::new();
    let (a, b) = (bus.add_node(), bus.add_node());
    bus.inject(BitFault {
        id: Some(0),
        not_before: 0,
        at_bit: 20,
    });
    bus.queue(a, 0, frame(0, &[]), 0).unwrap();
    let events = bus.run_until(1000);
    // Error at bit 20; flag 6 + delimiter 8 + intermission 3 from bit 21: idle at 38.
    assert_eq!(
        events[0],
        Event::ErrorFrame {
            node: a,
            mailbox: 0,
            frame: frame(0, &[]),
            start: 0,
            at: 20,
            kind: ErrorKind::Bit,
            idle_at: 38
        }
    );
    assert_eq!(sent(&events), vec![(0, a, 38, 88)]);
    // Transmitter +8 −1, receiver +1 −1.
    assert_eq!(bus.error_counters(a), (7, 0));
    assert_eq!(bus.error_counters(b), (0, 0));
}

#[test]
fn alone_on_the_bus_a_frame_is_never_acknowledged() {
    let mut bus = Bus::new();
    let a = bus.add_node();
    bus.queue(a, 0, frame(0, &[]), 0).unwrap();
    let events = bus.run_until(1_200);
    let attempts: Vec<(u64, u64)> = events
        .iter()
        .filter_map(|e| match *e {
            Event::ErrorFrame {
                start, at, kind, ..
            } => {
                assert_eq!(kind, ErrorKind::Ack);
                Some((start, at))
            }
            _ => None,
        })
        .collect();
    // 40 stuffed bits (34 + 6), CRC delimiter at 40, ACK slot at bit 41; idle 18 bits later: 59.
    assert_eq!(attempts[0], (0, 41));
    assert_eq!(attempts[1].0, 59);
    // Sixteen ACK errors make it error-passive (TEC 128) at 16 × 59 = 944 …
    assert_eq!(attempts[15].0, 15 * 59);
    assert!(events.contains(&Event::StateChange {
        node: a,
        at: 944,
        state: ErrorState::Passive
    }));
    // … after which it suspends 8 bits between attempts, and its ACK errors no longer count.
    assert_eq!(attempts[16].0, 944 + 8);
    assert_eq!(attempts[17].0, 944 + 8 + 67);
    assert_eq!(bus.error_counters(a).0, 128);
    // Someone plugs in: the next attempt is acknowledged.
    let b = bus.add_node();
    let events = bus.run_until(2_000);
    let last = attempts.last().unwrap().0 + 67;
    assert_eq!(sent(&events), vec![(0, a, last, last + 50)]);
    assert_eq!(bus.error_counters(a).0, 127);
    assert!(bus.mailboxes(b).iter().all(Option::is_none));
}

#[test]
fn an_unplugged_node_neither_sends_nor_receives() {
    let mut bus = Bus::new();
    let (a, b, c) = (bus.add_node(), bus.add_node(), bus.add_node());
    bus.set_plugged(b, false, 0);
    bus.queue(b, 0, frame(0x010, &[]), 0).unwrap();
    bus.queue(a, 0, frame(0x400, &[]), 0).unwrap();
    let events = bus.run_until(500);
    let l = u64::from(frame_bits(&frame(0x400, &[])));
    assert_eq!(sent(&events), vec![(0x400, a, 0, l)]);
    let Event::Sent { receivers, .. } = events[0] else {
        panic!()
    };
    assert_eq!(receivers, 1 << c);
    // Back at 500: it listens for an intermission before its frame goes out.
    bus.set_plugged(b, true, 500);
    assert_eq!(bus.run_until(503).len(), 0);
    let events = bus.run_until(1000);
    assert_eq!(sent(&events)[0].0, 0x010);
    assert_eq!(sent(&events)[0].2, 503);
}

#[test]
fn thirty_two_errors_take_a_node_off_the_bus_and_it_recovers() {
    let mut bus = Bus::new();
    let (a, _b) = (bus.add_node(), bus.add_node());
    for _ in 0..32 {
        bus.inject(BitFault {
            id: None,
            not_before: 0,
            at_bit: 20,
        });
    }
    bus.queue(a, 0, frame(0, &[]), 0).unwrap();
    let events = bus.run_until(10_000);
    // 16 active attempts 38 bits apart: passive at 608, then 46 bits apart (suspend 8) from 616;
    // the 32nd starts at 616 + 15 × 46 = 1306 and ends at 1344: bus-off until 1344 + 1408.
    assert!(events.contains(&Event::StateChange {
        node: a,
        at: 608,
        state: ErrorState::Passive
    }));
    assert!(events.contains(&Event::StateChange {
        node: a,
        at: 1344,
        state: ErrorState::BusOff
    }));
    assert!(events.contains(&Event::StateChange {
        node: a,
        at: 2752,
        state: ErrorState::Active
    }));
    assert_eq!(sent(&events), vec![(0, a, 2752, 2802)]);
}

#[test]
fn a_completion_is_never_sooner_than_the_look_ahead() {
    // Pseudo-random traffic from three nodes: every frame that starts before t completes at or
    // after its start + MIN_FRAME_BITS, which is what lets the robot's boards run a quantum apart.
    let mut bus = Bus::new();
    let nodes = [bus.add_node(), bus.add_node(), bus.add_node()];
    let mut seed = 0x1234_5678u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        seed >> 8
    };
    let mut time = 0;
    let mut count = 0;
    for quantum in 1..2_000u64 {
        for &n in &nodes {
            for m in 0..MAILBOXES {
                if bus.mailboxes(n)[m].is_none() && next() % 4 == 0 {
                    let id = (next() % 0x7FF) as u16;
                    let len = (next() % 9) as usize;
                    let _ = bus.queue(
                        n,
                        m,
                        frame(id, &[0xA5; 8][..len]),
                        time + u64::from(next() % 40),
                    );
                }
            }
        }
        time = quantum * 40;
        for e in bus.run_until(time) {
            if let Event::Sent { start, end, .. } = e {
                assert!(start < time && end >= start + u64::from(MIN_FRAME_BITS));
                count += 1;
            }
        }
    }
    assert!(count > 500, "{count} frames");
}

#[test]
fn a_babbling_node_sends_back_to_back_and_lower_identifiers_still_win() {
    // Node b babbles 0x400 from 1000 to 3000; node a queues 0x100 (lower: wins the next
    // arbitration) and 0x500 (higher: waits until the babbling stops); node c only listens.
    let mut bus = Bus::new();
    let (a, b, c) = (bus.add_node(), bus.add_node(), bus.add_node());
    let babble = frame(0x400, &[0xA5; 8]);
    let l = u64::from(frame_bits(&babble));
    let l1 = u64::from(frame_bits(&frame(0x100, &[1])));
    let l5 = u64::from(frame_bits(&frame(0x500, &[5])));
    bus.babble(b, babble, 1000, 3000);
    assert!(bus.babbling(b, 2999) && !bus.babbling(b, 3000) && !bus.babbling(a, 0));
    bus.queue(a, 0, frame(0x500, &[5]), 1100).unwrap();
    bus.queue(a, 1, frame(0x100, &[1]), 1100).unwrap();
    let events = bus.run_until(10_000);
    let got = sent(&events);
    // First babble at 1000; 0x100 takes the next arbitration; then babble back to back (each
    // start one intermission after the last completion) up to the last start before 3000.
    let mut want = vec![(0x400, b, 1000, 1000 + l)];
    let s = 1000 + l + 3;
    want.push((0x100, a, s, s + l1));
    let mut s = s + l1 + 3;
    while s < 3000 {
        want.push((0x400, b, s, s + l));
        s += l + 3;
    }
    want.push((0x500, a, s, s + l5));
    assert_eq!(got, want);
    // Every babbling frame was pending from the previous completion (or the fault's start),
    // reported from no mailbox of the node's, and heard by the others.
    for e in &events {
        if let Event::Sent {
            node,
            mailbox,
            queued_at,
            start,
            receivers,
            ..
        } = *e
        {
            if node == b {
                assert_eq!(mailbox, BABBLE_MAILBOX);
                assert!(
                    queued_at <= start && start - queued_at <= 3 + l1 + 3,
                    "{e:?}"
                );
                assert_eq!(receivers, 1 << a | 1 << c);
            }
        }
    }
    assert_eq!(bus.mailboxes(b), [None; MAILBOXES]);
}

#[test]
fn a_babbling_node_with_the_lowest_identifier_holds_the_bus_until_stopped() {
    let mut bus = Bus::new();
    let (a, b) = (bus.add_node(), bus.add_node());
    let babble = frame(0x001, &[]);
    let l = u64::from(frame_bits(&babble));
    bus.babble(b, babble, 0, u64::MAX);
    bus.queue(a, 0, frame(0x100, &[]), 0).unwrap();
    let events = bus.run_until(2000);
    assert!(sent(&events).iter().all(|&(id, ..)| id == 0x001));
    assert_eq!(sent(&events).len() as u64, 2000_u64.div_ceil(l + 3));
    // Stopped at 2500: the frame that started before completes; then 0x100 goes out.
    bus.stop_babbling(b, 2500);
    let events = bus.run_until(5000);
    let got = sent(&events);
    let last = got.iter().rposition(|&(id, ..)| id == 0x001).unwrap();
    assert!(got[last].2 < 2500);
    assert_eq!(
        got[last + 1],
        (
            0x100,
            a,
            got[last].3 + 3,
            got[last].3 + 3 + u64::from(frame_bits(&frame(0x100, &[])))
        )
    );
    assert_eq!(got.len(), last + 2);
}

#[test]
fn an_abort_takes_a_waiting_frame_back_but_not_one_already_sent() {
    // Node b babbles 0x400 from 0; node a's 0x500 waits behind it in mailbox 0 and is aborted at
    // 2000, its mailbox then free for 0x100, which wins the next arbitration. Node a's 0x050, sent
    // at once, is gone from its mailbox: aborting it afterwards finds nothing.
    let mut bus = Bus::new();
    let (a, b) = (bus.add_node(), bus.add_node());
    bus.babble(b, frame(0x400, &[0xA5; 8]), 0, 5000);
    bus.queue(a, 1, frame(0x050, &[]), 0).unwrap();
    bus.queue(a, 0, frame(0x500, &[5]), 100).unwrap();
    let before = sent(&bus.run_until(2000));
    assert_eq!(before[0].0, 0x050);
    assert!(before[1..].iter().all(|s| s.0 == 0x400), "{before:?}");
    assert_eq!(bus.abort(a, 1), None, "0x050 went out: nothing to abort");
    let aborted = bus.abort(a, 0).expect("0x500 still waits");
    assert_eq!((aborted.frame.id, aborted.queued_at), (0x500, 100));
    assert_eq!(bus.mailboxes(a), [None; MAILBOXES]);
    assert_eq!(bus.abort(a, 0), None, "an empty mailbox");
    assert_eq!(bus.abort(a, 7), None, "no such mailbox");
    bus.queue(a, 0, frame(0x100, &[1]), 2000).unwrap();
    let after = sent(&bus.run_until(10_000));
    let first_after = after.iter().position(|s| s.0 == 0x100).expect("0x100 sent");
    // At most the babbling frame already on the bus goes before it; 0x500 never goes out.
    assert!(first_after <= 1, "{after:?}");
    assert!(after.iter().all(|s| s.0 != 0x500), "{after:?}");
}

#[test]
fn a_node_alone_on_the_bus_starts_when_it_is_idle() {
    let mut bus = Bus::new();
    let (a, b) = (bus.add_node(), bus.add_node());
    assert_eq!(bus.alone_from(a), Some(0));
    bus.queue(a, 0, frame(0x605, &[1, 2]), 100).unwrap();
    bus.run_until(101);
    let end = 100 + u64::from(frame_bits(&frame(0x605, &[1, 2])));
    // After the frame and its intermission, for either node.
    assert_eq!(bus.alone_from(b), Some(end + 3));
    assert_eq!(bus.alone_from(a), Some(end + 3));
    // No one to acknowledge, a fault to come, a babbling controller: no such time.
    bus.set_plugged(b, false, end);
    assert_eq!(bus.alone_from(a), None);
    bus.set_plugged(b, true, end);
    assert_eq!(bus.alone_from(a), Some(end + 3));
    assert_eq!(bus.alone_from(b), Some(end + 3));
    bus.inject(BitFault {
        id: None,
        not_before: 0,
        at_bit: 5,
    });
    assert_eq!(bus.alone_from(a), None);
    let mut bus = Bus::new();
    let (a, b) = (bus.add_node(), bus.add_node());
    bus.babble(b, frame(0x700, &[]), 0, u64::MAX);
    assert_eq!(bus.alone_from(b), None);
    assert_eq!(bus.alone_from(a), Some(0));
    assert_eq!(bus.alone_from(7), None);
}
