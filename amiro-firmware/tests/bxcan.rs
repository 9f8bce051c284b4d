//! The bxCAN driver against a register-level model of the controller: set-up, ID-ordered
//! mailboxes with non-blocking displacement, equal-ID order, FIFO reads with DLC and frame-type
//! checks, overruns, and the error-state monitor.
use std::cell::RefCell;

use amiro_can::{CanId, Frame, Kind};
use amiro_firmware::bxcan::model::{Failure, Model, Reception, RxRequest};
use amiro_firmware::bxcan::{self, BusState, ErrorMonitor, Fifo0, InitError, Mailboxes};
use amiro_firmware::can::{CanRx, CanTx, Completion, RxEvent, Transmit};

/// The driver's register model (`bxcan::model`, the one the QEMU build runs), shared between the
/// driver's halves and the test, which plays the bus.
type Can = RefCell<Model>;

/// A configured controller on the bus.
fn configured() -> Can {
    let can = RefCell::new(Model::new());
    bxcan::configure(&&can, 0x012D_0001).unwrap();
    can
}

/// The bus takes the mailbox the controller offers (lowest ID) and acknowledges it: its (id, data).
fn bus_sends_one(can: &Can) -> Option<(u16, Vec<u8>)> {
    let mut model = can.borrow_mut();
    let i = model.offered()?;
    let request = model.request(i)?;
    assert!(model.transmitted(i));
    Some((request.id as u16, request.payload().to_vec()))
}

/// A raw frame from the bus: (RIR identifier bits, DLC, data) straight into FIFO 0.
fn deliver(can: &Can, rir: u32, dlc: u8, data: [u8; 8]) -> Reception {
    can.borrow_mut().store(&RxRequest {
        id: if rir & 0b100 != 0 {
            rir >> 3
        } else {
            rir >> 21
        },
        extended: rir & 0b100 != 0,
        remote: rir & 0b010 != 0,
        dlc,
        data,
    })
}

/// Whether the driver asked for mailbox `i`'s abort (TSR.ABRQx).
fn abort_requested(can: &Can, i: usize) -> bool {
    can.borrow().read(0x008) & (1 << (8 * i + 7)) != 0
}

fn frame(id: u16, data: &[u8]) -> Frame {
    let id = CanId::try_from(id).unwrap();
    assert_eq!(id.kind(), Kind::Sensor);
    Frame::new(id, data).unwrap()
}

fn drain_completions(tx: &mut Mailboxes<&Can>) -> Vec<Completion> {
    let mut out = Vec::new();
    tx.completed(&mut |c| out.push(c));
    out
}

#[test]
fn configure_sets_timing_filter_interrupts_and_auto_recovery() {
    let can = configured();
    let model = can.borrow();
    assert_eq!(model.read(0x01C), 0x012D_0001);
    let mcr = model.read(0x000);
    assert_ne!(mcr & (1 << 6), 0, "automatic bus-off management");
    assert_eq!(mcr & (1 << 2), 0, "transmit order by identifier, not FIFO");
    assert_eq!(mcr & (1 << 4), 0, "automatic retransmission");
    assert_eq!(mcr & 0b11, 0, "left init and sleep");
    assert_eq!(model.read(0x004) & 0b11, 0, "INAK and SLAK clear");
    assert!(model.on_bus());
    assert_eq!(model.read(0x21C) & 1, 1, "bank 0 active");
    assert_eq!(
        model.read(0x244),
        (0x400 << 21) | 0b110,
        "mask: C/S, IDE, RTR"
    );
    assert_eq!(model.read(0x240), 0);
    assert_eq!(model.read(0x200) & 1, 0, "filters out of initialisation");
    assert_eq!(model.ignored_writes(), 0, "every write landed");
    drop(model);
    // What the registers `configure` wrote let through (the model's bank 0) is `passes_filter`:
    // the rule the robot host's lookahead reads off the link too (amiro-trace::robot_link).
    for id in 0..0x800u16 {
        let passed = can
            .borrow_mut()
            .receive(&RxRequest::standard(id, 0, [0; 8]));
        assert_eq!(
            passed == Reception::Stored,
            bxcan::passes_filter(id),
            "{id:03X}"
        );
        assert_eq!(
            amiro_trace::robot_link::reaches_software(id),
            bxcan::passes_filter(id),
            "{id:03X}"
        );
        let _ = Fifo0::new(&can).receive();
    }
    assert!(bxcan::passes_filter(0x205) && !bxcan::passes_filter(0x610));
    // Extended and remote frames never reach FIFO 0.
    let mut model = can.borrow_mut();
    for (extended, remote) in [(true, false), (false, true)] {
        let frame = RxRequest {
            extended,
            remote,
            ..RxRequest::standard(0x205, 0, [0; 8])
        };
        assert_eq!(model.receive(&frame), Reception::Filtered);
    }
    let ier = model.read(0x014);
    for (bit, what) in [
        (0, "TMEIE"),
        (1, "FMPIE0"),
        (3, "FOVIE0"),
        (9, "EPVIE"),
        (10, "BOFIE"),
        (15, "ERRIE"),
    ] {
        assert_ne!(ier & (1 << bit), 0, "{what}");
    }
}

#[test]
fn configure_never_waits_for_ever() {
    let mut dead = Model::new();
    dead.unclocked = true;
    let dead = RefCell::new(dead);
    assert_eq!(
        bxcan::configure(&&dead, 1),
        Err(InitError::EnterInitTimeout)
    );
    let mut stuck = Model::new();
    stuck.bus_held_dominant = true;
    let stuck = RefCell::new(stuck);
    assert_eq!(
        bxcan::configure(&&stuck, 1),
        Err(InitError::LeaveInitTimeout)
    );
    // Configured but not on the bus: nothing is offered, nothing received.
    let stuck = stuck.into_inner();
    assert!(!stuck.on_bus());
}

#[test]
fn frames_leave_most_urgent_first_and_are_reported_sent() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x610, 0x620] {
        assert_eq!(tx.transmit(&frame(id, &[1, 2, 3])), Transmit::Queued);
    }
    assert_eq!(tx.pending(), 3);
    assert_eq!(can.borrow().read(0x008) >> 26 & 0b111, 0, "no TME bit");
    assert_eq!(bus_sends_one(&can), Some((0x610, vec![1, 2, 3])));
    assert!(
        can.borrow().tx_interrupt(),
        "RQCP raises the transmit interrupt"
    );
    let done = drain_completions(&mut tx);
    assert_eq!(done, vec![Completion::Sent(frame(0x610, &[1, 2, 3]))]);
    assert!(!can.borrow().tx_interrupt(), "acknowledged");
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x620));
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x630));
    assert_eq!(bus_sends_one(&can), None);
    assert_eq!(can.borrow().ignored_writes(), 0);
}

#[test]
fn the_mailbox_gets_the_whole_data_buffer_and_the_bus_only_the_dlc_bytes() {
    // `transmit` writes all 8 data bytes (a copy of fixed size); the DLC decides what is sent, so
    // bytes past it in a frame's buffer (possible from `Frame::from_parts`) never reach the bus.
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    let id = CanId::try_from(0x605).unwrap();
    let padded = Frame::from_parts(id, 2, [7, 8, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE]).unwrap();
    assert_eq!(tx.transmit(&padded), Transmit::Queued);
    assert_eq!(bus_sends_one(&can), Some((0x605, vec![7, 8])));
    assert_eq!(tx.transmit(&frame(0x606, &[])), Transmit::Queued);
    assert_eq!(bus_sends_one(&can), Some((0x606, vec![])));
    let eight = frame(0x607, &[1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(tx.transmit(&eight), Transmit::Queued);
    assert_eq!(
        bus_sends_one(&can),
        Some((0x607, vec![1, 2, 3, 4, 5, 6, 7, 8]))
    );
}

#[test]
fn an_urgent_frame_displaces_the_least_urgent_without_waiting() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x640, 0x620] {
        tx.transmit(&frame(id, &[0]));
    }
    // Full: the urgent frame asks for an abort of 0x640 and returns at once.
    assert_eq!(tx.transmit(&frame(0x508, &[9])), Transmit::Busy);
    assert!(
        abort_requested(&can, 1),
        "abort requested on the least urgent mailbox"
    );
    assert!(can.borrow().request(1).unwrap().abort_requested);
    // A second offer does not request a second abort of a mailbox already aborting.
    assert_eq!(tx.transmit(&frame(0x509, &[9])), Transmit::Busy);
    assert!(!abort_requested(&can, 0) && !abort_requested(&can, 2));
    // The controller completes the abort: the aborted frame comes back for the queue.
    assert!(can.borrow_mut().abort(1));
    assert!(!abort_requested(&can, 1), "ABRQ clears with the mailbox");
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Aborted(frame(0x640, &[0]))]
    );
    assert_eq!(tx.transmit(&frame(0x508, &[9])), Transmit::Queued);
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x508));
}

#[test]
fn an_abort_of_a_frame_on_the_bus_ends_as_its_transmission_does() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x640, 0x620] {
        tx.transmit(&frame(id, &[0]));
    }
    tx.transmit(&frame(0x508, &[9]));
    // 0x640 was on the bus when the abort came: it is acknowledged all the same.
    assert!(can.borrow_mut().transmitted(1));
    assert!(!can.borrow_mut().abort(1), "nothing left to abort");
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Sent(frame(0x640, &[0]))]
    );
    // 0x630 asked to abort, then loses an arbitration: it ends aborted instead of being retried.
    tx.transmit(&frame(0x508, &[9]));
    tx.transmit(&frame(0x509, &[9]));
    assert!(abort_requested(&can, 0));
    assert!(can.borrow_mut().failed(0, Failure::ArbitrationLost));
    let tsr = can.borrow().read(0x008);
    assert_eq!(tsr & 0b111, 0b101, "RQCP and ALST, no TXOK");
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Aborted(frame(0x630, &[0]))]
    );
}

#[test]
fn a_lost_arbitration_is_retried_automatically() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    tx.transmit(&frame(0x630, &[1]));
    assert!(can.borrow_mut().failed(0, Failure::ArbitrationLost));
    assert!(can.borrow_mut().failed(0, Failure::Error));
    assert_eq!(
        can.borrow().read(0x008) & 0b1111,
        0b1100,
        "ALST, TERR, still pending"
    );
    assert!(drain_completions(&mut tx).is_empty());
    assert_eq!(bus_sends_one(&can), Some((0x630, vec![1])));
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Sent(frame(0x630, &[1]))]
    );
    assert_eq!(
        can.borrow().read(0x008) & 0b1111,
        0,
        "RQCP cleared the flags"
    );
}

#[test]
fn a_mailbox_is_reused_only_after_its_completion_is_collected() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x610, 0x620] {
        tx.transmit(&frame(id, &[1]));
    }
    // The controller empties mailbox 1 after the interrupt collected the completions and before
    // it fills the mailboxes: the frame after must not go into the mailbox whose completion is
    // unread, or the next interrupt would report it sent.
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x610));
    assert_eq!(tx.transmit(&frame(0x640, &[2])), Transmit::Busy);
    assert_eq!(tx.pending(), 3);
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Sent(frame(0x610, &[1]))]
    );
    assert_eq!(tx.transmit(&frame(0x640, &[2])), Transmit::Queued);
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x620));
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Sent(frame(0x620, &[1]))]
    );
    // A frame of the identifier that just completed may go in at once.
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x630));
    assert_eq!(tx.transmit(&frame(0x630, &[3])), Transmit::Queued);
    assert_eq!(can.borrow().ignored_writes(), 0);
}

#[test]
fn a_less_urgent_frame_never_displaces() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x610u16, 0x611, 0x612] {
        tx.transmit(&frame(id, &[0]));
    }
    assert_eq!(tx.transmit(&frame(0x700, &[0])), Transmit::Busy);
    assert!((0..3).all(|i| !abort_requested(&can, i)));
}

#[test]
fn equal_identifiers_leave_in_queue_order() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    assert_eq!(tx.transmit(&frame(0x61F, &[0, 1, 2])), Transmit::Queued);
    // The second sample of the same topic must wait: mailboxes with equal IDs go by number.
    assert_eq!(tx.transmit(&frame(0x61F, &[1, 1, 2])), Transmit::Busy);
    bus_sends_one(&can);
    drain_completions(&mut tx);
    assert_eq!(tx.transmit(&frame(0x61F, &[1, 1, 2])), Transmit::Queued);
}

#[test]
fn the_controller_offers_by_identifier_then_mailbox_number_or_in_request_order() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x610, 0x620] {
        tx.transmit(&frame(id, &[0]));
    }
    let model = can.borrow();
    assert_eq!(model.offered(), Some(1));
    // CODE: no mailbox free; LOW: mailbox 0 (0x630) goes last.
    assert_eq!(model.read(0x008) >> 29, 0b001);
    drop(model);
    // TXFP set: the oldest request first.
    let txfp = can.borrow().read(0x000) | (1 << 2);
    can.borrow_mut().write(0x000, txfp);
    assert_eq!(can.borrow().offered(), Some(0));
    assert_eq!(can.borrow().read(0x008) >> 29, 0b100, "LOW: the newest");
    // A write to a pending mailbox is ignored, as on the chip.
    can.borrow_mut().write(0x188, 0xFFFF_FFFF);
    assert_eq!(can.borrow().ignored_writes(), 1);
    assert_eq!(can.borrow().request(0).unwrap().data, [0; 8]);
}

#[test]
fn fifo_clamps_long_length_codes_and_marks_foreign_frames() {
    let can = configured();
    let mut rx = Fifo0::new(&can);
    assert_eq!(rx.receive(), None);
    deliver(&can, 0x205 << 21, 15, [1, 2, 3, 4, 5, 6, 7, 8]);
    deliver(&can, (0x205 << 21) | 0b100, 2, [9; 8]); // extended, its data not passed on
    deliver(&can, (0x205 << 21) | 0b010, 0, [0; 8]); // remote
    assert!(can.borrow().rx0_interrupt());
    match rx.receive() {
        Some(RxEvent::Frame(f)) => {
            assert_eq!(f.id, 0x205);
            assert_eq!(f.payload(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        }
        other => panic!("{other:?}"),
    }
    for _ in 0..2 {
        match rx.receive() {
            Some(RxEvent::Frame(f)) => assert_eq!((f.id, f.len, f.data), (u16::MAX, 0, [0; 8])),
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(rx.receive(), None);
    assert!(!can.borrow().rx0_interrupt(), "FIFO empty");
}

#[test]
fn an_overrun_is_reported_once_per_event_and_cleared() {
    let can = configured();
    let mut rx = Fifo0::new(&can);
    for i in 0..5u8 {
        let stored = deliver(&can, 0x205 << 21, 1, [i, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(stored == Reception::Stored, i < 3, "frame {i}");
    }
    assert_eq!(rx.receive(), Some(RxEvent::Overrun));
    let mut first_bytes = Vec::new();
    while let Some(event) = rx.receive() {
        match event {
            RxEvent::Frame(f) => first_bytes.push(f.data[0]),
            other => panic!("{other:?}"),
        }
    }
    // FIFO lock mode is off (`configure` leaves RFLM clear): each frame that found the FIFO full
    // overwrote the newest one, so the last frame is read and frame 2 and 3 are lost.
    assert_eq!(first_bytes, vec![0, 1, 4]);
    assert_eq!(can.borrow().read(0x00C) & (1 << 4), 0, "FOVR cleared");
}

#[test]
fn error_monitor_counts_passive_and_bus_off_episodes() {
    let can = configured();
    let mut monitor = ErrorMonitor::new(&can);
    let set = |tec, rec, bus_off| can.borrow_mut().set_error_counters(tec, rec, bus_off);
    assert_eq!(monitor.poll(), None);
    set(100, 0, false);
    assert!(
        can.borrow().sce_interrupt(),
        "a change of state raises ERRI"
    );
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Warning));
    assert!(!can.borrow().sce_interrupt(), "acknowledged");
    set(130, 0, false);
    let change = monitor.poll().unwrap();
    assert_eq!(
        (change.from, change.to, change.tec),
        (BusState::Warning, BusState::Passive, 130)
    );
    set(255, 0, true);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::BusOff));
    // Hardware recovery: back through passive to active; that passive is not a new episode.
    set(128, 0, false);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Passive));
    set(0, 0, false);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Active));
    assert_eq!(monitor.passive_episodes(), 1);
    assert_eq!(monitor.bus_off_episodes(), 1);
    // A receive counter alone makes the controller error-passive too.
    set(0, 200, false);
    let change = monitor.poll().unwrap();
    assert_eq!((change.to, change.rec), (BusState::Passive, 200));
}

#[test]
fn one_collection_clears_every_completion_it_found_and_no_abort_request() {
    let can = configured();
    let mut tx = Mailboxes::new(&can);
    for id in [0x630u16, 0x640, 0x620] {
        tx.transmit(&frame(id, &[4]));
    }
    // The least urgent (0x640) asked to abort for a more urgent frame, still pending; then the
    // other two are sent.
    assert_eq!(tx.transmit(&frame(0x508, &[9])), Transmit::Busy);
    assert!(abort_requested(&can, 1));
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x620));
    assert_eq!(bus_sends_one(&can).map(|(id, _)| id), Some(0x630));
    // The driver clears both completions with one write and reports them in mailbox order; the
    // abort request of the pending mailbox is not a flag it clears.
    assert_eq!(
        drain_completions(&mut tx),
        vec![
            Completion::Sent(frame(0x630, &[4])),
            Completion::Sent(frame(0x620, &[4]))
        ]
    );
    let tsr = can.borrow().read(0x008);
    let rqcp = (1 << 0) | (1 << 8) | (1 << 16);
    assert_eq!(tsr & rqcp, 0, "every completion found is cleared");
    assert!(abort_requested(&can, 1), "the abort stays under way");
    assert!(
        drain_completions(&mut tx).is_empty(),
        "nothing reported twice"
    );
    // The abort ends: the next collection hands the frame back.
    assert!(can.borrow_mut().abort(1));
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Aborted(frame(0x640, &[4]))]
    );
    assert_eq!(can.borrow().ignored_writes(), 0);
}
