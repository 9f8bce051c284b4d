//! Which publisher rows a publisher task serves next: the walks of the publisher table behind
//! `crate::publisher::serve_level`, apart from the task's locks and clock so they run on the host.
//!
//! A task serves the CAN priorities of its `levels` (DiWheelDrive and PowerManagement one per task,
//! LightRing all four from one). Its next release is found and taken in one walk of the table for
//! all its levels ([`take_next`]), and the walk that finds none due finds the earliest due time the
//! task parks on, and the one that takes a release says what comes after it ([`After`]): one walk a
//! release, where one walk per level, and walks of their own to find, take and park, each cost every
//! job (the execution-time analysis charges every walk to every job; "One topic's job").
use amiro_can::Priority;
use amiro_sensors::handler::{Release, SensorDataHandler, LEVELS};

/// Where each CAN priority comes in a publisher task's `levels` (its first place there), or
/// [`Ranks::NOT_SERVED`]: taken once from the board's slice, so that finding the next due time or
/// the next release of all the task's levels is one walk of the publisher table, not one per level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ranks([u8; LEVELS]);

impl Ranks {
    /// A level the task does not serve.
    pub const NOT_SERVED: u8 = u8::MAX;

    /// The ranks of the board's slice `levels` (a level listed twice keeps its first place).
    pub fn of(levels: &[Priority]) -> Self {
        let mut ranks = [Self::NOT_SERVED; LEVELS];
        // An index loop (as the walks below), so that the execution-time analysis finds each of
        // these loops at a line of its own (the bounds files key loops by function and line).
        let mut rank = 0;
        while let Some(&level) = levels.get(rank) {
            if let Some(slot) = ranks.get_mut(usize::from(level.bits())) {
                if *slot == Self::NOT_SERVED {
                    *slot = u8::try_from(rank).unwrap_or(Self::NOT_SERVED - 1);
                }
            }
            rank += 1;
        }
        Ranks(ranks)
    }

    /// `level`'s place in the task's `levels`, or `None` when the task does not serve it.
    pub fn of_level(self, level: Priority) -> Option<u8> {
        Some(self.rank_of(level)).filter(|&rank| rank != Self::NOT_SERVED)
    }

    /// `level`'s place, [`Ranks::NOT_SERVED`] when the task does not serve it: the table walks'
    /// per-row look-up (a level's bits are below `LEVELS`, so the index needs no check).
    #[inline(always)]
    fn rank_of(self, level: Priority) -> u8 {
        self.0[usize::from(level.bits()) % LEVELS]
    }
}

/// The earliest due time of the running publishers and pending one-shots at the task's levels, or
/// `None` if none of its levels has anything to do: the minimum of [`SensorDataHandler::next_due`]
/// over the levels, in one walk of the table. It may lie in the past: the task is behind.
pub fn next_due(handler: &SensorDataHandler, ranks: Ranks) -> Option<u64> {
    let rows = handler.publishers();
    let mut earliest: Option<u64> = None;
    let mut i = 0;
    while let Some(row) = rows.get(i) {
        if ranks.of_level(row.priority()).is_some() {
            if let Some(due) = row.next_due_us() {
                earliest = Some(earliest.map_or(due, |e| e.min(due)));
            }
        }
        i += 1;
    }
    earliest
}

/// What [`take_next`] found in its walk of the publisher table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Next {
    /// The release taken, with its row's period (which the release keeps), and what the task
    /// does after it ([`After`]: what a walk of the table as the take left it would answer).
    Release(Release, u32, After),
    /// Nothing of the task's levels was due: their earliest due time ([`next_due`]'s; `None` when
    /// none of them has anything to do), which lies after the walk's `now_us`.
    Park(Option<u64>),
}

/// What a task does after the release [`take_next`] took, worked out in the same walk: the answer
/// the next walk at the same `now_us` would give while the table is as the take left it, so that
/// a job's last release needs no walk of its own to find the due time it parks on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum After {
    /// Another row of the task's levels is due: walk again (its release is the next walk's).
    More,
    /// Nothing else is due: park until this due time (`None`: until a command wakes the task).
    Park(Option<u64>),
}

/// Takes the next release due at `now_us` for a task of `ranks`, or says when to look again, in one
/// walk of the table. The release is that of the level of the task's `levels` that comes first and
/// has a row due, its earliest due row there (ties to the row first in the table, which is the
/// lower topic byte: `SensorDataHandler::new` fills the table in `Topic::ALL`'s order): taking
/// releases until this parks hands out the releases the levels' own loops would (`for level in
/// levels`, take each level's [`SensorDataHandler::take_next_release`] until none), in their
/// order. The walk that finds nothing due finds the earliest due time as it goes, so the task
/// parks on it without another walk ([`next_due`]); where the task found a level and then took
/// that level's release, each was a walk of its own. The walk that takes a release keeps the
/// second-least key as well, so it also says what comes after the release ([`After`]): the next
/// walk's answer, as long as no command changed the table in between (a command that gives a row
/// of the task's levels an earlier due time wakes the task, which then walks again).
// Not inlined: one copy for every publisher task's loop and the suspending one (flash).
#[inline(never)]
pub fn take_next(handler: &mut SensorDataHandler, ranks: Ranks, now_us: u64) -> Next {
    let rows = handler.publishers();
    // One key per row of a served level with something to do, as one word: its rank when due at
    // `now_us` (NOT_SERVED when not) above its due time. The least key is the release to take
    // when any row is due (every served rank is below NOT_SERVED), and else the earliest due
    // time: one comparison a pass finds both (this walk is most of the code around a release's
    // sample: docs/analysis.md, "One topic's job"). The second-least key is the rest of the
    // table's answer once the least row is taken. Ties go to the row first in the table.
    let mut least = NO_KEY;
    let mut second = NO_KEY;
    let mut at = usize::MAX;
    let mut i = 0;
    while let Some(row) = rows.get(i) {
        let rank = ranks.rank_of(row.priority());
        if rank != Ranks::NOT_SERVED {
            if let Some(due) = row.next_due_us() {
                let key_rank = if due <= now_us {
                    rank
                } else {
                    Ranks::NOT_SERVED
                };
                let key = key_of(key_rank, due);
                if key < least {
                    second = least;
                    least = key;
                    at = i;
                } else if key < second {
                    second = key;
                }
            }
        }
        i += 1;
    }
    if !is_due(least) {
        // Nothing due: park on the earliest due time (none without a row that has one).
        return Next::Park(due_in(least));
    }
    let period_us = rows.get(at).map_or(0, |row| row.period_us());
    let Some(release) = handler.take_release_of_row(at, now_us) else {
        // Not taken: the walk found the row due, and nothing has changed the table since; were
        // it not so, the task would look again at once (the row's due time, not after `now_us`).
        return Next::Park(due_in(least));
    };
    // The next walk's answer: another row due (the second key), or else the earliest of the
    // other rows' due times and the taken row's next (none for a one-shot, which stopped); a
    // taken row due again at `now_us` (it cannot be: its next release lies after `now_us`) is
    // walked for, as any other.
    let taken = handler
        .publishers()
        .get(at)
        .and_then(|row| row.next_due_us())
        .map_or(NO_KEY, |next| key_of(Ranks::NOT_SERVED, next));
    let after = if is_due(second) || due_in(taken).is_some_and(|next| next <= now_us) {
        After::More
    } else {
        After::Park(due_in(second.min(taken)))
    };
    Next::Release(release, period_us, after)
}

/// Whether a walk key ([`key_of`]) is a row due at the walk's time (a served rank).
#[inline(always)]
fn is_due(key: u64) -> bool {
    key >> KEY_DUE_BITS != u64::from(Ranks::NOT_SERVED)
}

/// The due time a walk key holds, `None` for [`NO_KEY`].
#[inline(always)]
fn due_in(key: u64) -> Option<u64> {
    Some(key & DUE_MASK).filter(|&due| due != DUE_MASK)
}

/// The bits of a walk key ([`key_of`]) below its rank: a due time's.
const KEY_DUE_BITS: u32 = 56;

/// A walk key's due-time bits.
const DUE_MASK: u64 = (1 << KEY_DUE_BITS) - 1;

/// No key: above every row's ([`key_of`] keeps a due time's bits below all ones).
const NO_KEY: u64 = u64::MAX;

/// A row's walk key: `rank` above the row's due time, so that one comparison of two words orders
/// rows by rank and then by due time. The due time is kept to 2^56 - 2 µs (2 284 years of
/// uptime): below that the order and the due times the walk answers are exact, and no key is
/// [`NO_KEY`].
#[inline(always)]
fn key_of(rank: u8, due: u64) -> u64 {
    (u64::from(rank) << KEY_DUE_BITS) | due.min(DUE_MASK - 1)
}

#[cfg(test)]
mod tests {
    use std::vec::Vec;

    use amiro_can::{Board, CanId, Kind, Priority, TimeUnit, Topic};
    use amiro_sensors::handler::{Release, SensorDataHandler};

    use super::{next_due, take_next, After, Next, Ranks};

    /// A random table of DiWheelDrive: each topic stopped, publishing at a random period and
    /// level, or a pending one-shot, set up at random times before `at`.
    fn random_table(seed: &mut u64, at: u64) -> SensorDataHandler {
        let mut next = || {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            *seed
        };
        let mut handler = SensorDataHandler::new(Board::DiWheelDrive);
        let topics: Vec<Topic> = handler.publishers().iter().map(|p| p.topic()).collect();
        for topic in topics {
            let level = Priority::ALL[(next() % 4) as usize];
            let id = CanId::new(Kind::Command, level, topic.byte()).raw();
            let set_up = next() % (at + 1);
            let period = 100 + (next() % 5_000) as u16;
            let [lo, hi] = period.to_le_bytes();
            let payload: &[u8] = match next() % 3 {
                0 => &[0],
                1 => &[1, lo, hi, TimeUnit::Micros as u8],
                _ => &[2],
            };
            let _ = handler.on_frame(set_up, id, payload);
        }
        handler
    }

    /// What the publisher did before it took the next level from one walk: each level of
    /// `levels` in turn, its releases until none.
    fn per_level(handler: &mut SensorDataHandler, levels: &[Priority], now: u64) -> Vec<Release> {
        let mut out = Vec::new();
        for &level in levels {
            while let Some(release) = handler.take_next_release(level, now) {
                out.push(release);
            }
        }
        out
    }

    /// What it does now: one walk takes each release, and the walk that takes none parks on the
    /// levels' earliest due time.
    fn one_walk(handler: &mut SensorDataHandler, levels: &[Priority], now: u64) -> Vec<Release> {
        let ranks = Ranks::of(levels);
        let mut out = Vec::new();
        loop {
            let before = handler.clone();
            match take_next(handler, ranks, now) {
                Next::Release(release, period_us, after) => {
                    assert_eq!(
                        after,
                        after_by_walk(handler, ranks, now),
                        "what comes after is the next walk's answer"
                    );
                    assert_eq!(
                        handler.publisher(release.topic).map(|p| p.period_us()),
                        Some(period_us),
                        "the period handed out is the released row's"
                    );
                    assert_eq!(
                        handler.counters().releases,
                        before.counters().releases + 1,
                        "the release is counted"
                    );
                    out.push(release);
                }
                Next::Park(due) => {
                    assert_eq!(
                        handler.publishers(),
                        before.publishers(),
                        "a park changes nothing"
                    );
                    assert_eq!(handler.counters(), before.counters());
                    assert_eq!(
                        due,
                        next_due(handler, ranks),
                        "it parks on the earliest due time"
                    );
                    assert!(
                        due.is_none_or(|due| due > now),
                        "nothing of the levels is due"
                    );
                    return out;
                }
            }
        }
    }

    /// What a walk of the table as it is now answers, as an [`After`] (the oracle of the walks'
    /// `After`): another release due, or the park.
    fn after_by_walk(handler: &SensorDataHandler, ranks: Ranks, now: u64) -> After {
        let mut copy = handler.clone();
        match take_next(&mut copy, ranks, now) {
            Next::Release(..) => After::More,
            Next::Park(due) => After::Park(due),
        }
    }

    const LEVEL_SETS: &[&[Priority]] = &[
        &[Priority::Urgent],
        &[Priority::High],
        &[Priority::Medium],
        &[Priority::Low],
        &[
            Priority::Urgent,
            Priority::High,
            Priority::Medium,
            Priority::Low,
        ],
        &[Priority::Low, Priority::Urgent],
        &[Priority::Medium, Priority::High, Priority::Medium],
        &[],
    ];

    #[test]
    fn one_walk_takes_the_releases_the_per_level_loops_take_in_their_order() {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut released = 0;
        for round in 0..400u64 {
            let at = 1 + round * 997;
            for levels in LEVEL_SETS {
                let table = random_table(&mut seed, at);
                let (mut old, mut new) = (table.clone(), table);
                for now in [at, at + 50, at + 10_000] {
                    let expected = per_level(&mut old, levels, now);
                    let got = one_walk(&mut new, levels, now);
                    assert_eq!(got, expected, "levels {levels:?} at {now}");
                    assert_eq!(new.publishers(), old.publishers());
                    released += got.len();
                }
            }
        }
        assert!(released > 1_000, "the tables released {released}");
    }

    #[test]
    fn one_walk_finds_the_earliest_due_time_of_the_levels() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut some = 0;
        for round in 0..400u64 {
            for levels in LEVEL_SETS {
                let table = random_table(&mut seed, round * 500);
                let expected = levels.iter().filter_map(|l| table.next_due(*l)).min();
                assert_eq!(next_due(&table, Ranks::of(levels)), expected, "{levels:?}");
                some += usize::from(expected.is_some());
            }
        }
        assert!(some > 1_000, "{some} tables had something due");
    }

    /// The walk as it was before its one key a row (a key of rank, due time and topic byte among
    /// the due rows, the earliest due time apart): the oracle of the property test below.
    fn take_next_before(handler: &mut SensorDataHandler, ranks: Ranks, now_us: u64) -> Next {
        let rows = handler.publishers();
        let mut best: Option<((u8, u64, u8), usize, u32)> = None;
        let mut earliest: Option<u64> = None;
        for (i, row) in rows.iter().enumerate() {
            if let (Some(rank), Some(due)) = (ranks.of_level(row.priority()), row.next_due_us()) {
                if due <= now_us {
                    let key = (rank, due, row.topic() as u8);
                    if best.is_none_or(|(best_key, _, _)| key < best_key) {
                        best = Some((key, i, row.period_us()));
                    }
                }
                earliest = Some(earliest.map_or(due, |e| e.min(due)));
            }
        }
        let Some((_, row, period_us)) = best else {
            return Next::Park(earliest);
        };
        match handler.take_release_of_row(row, now_us) {
            // What comes after: the old walk once more, on the table as the take left it.
            Some(release) => {
                let after = match take_next_before(&mut handler.clone(), ranks, now_us) {
                    Next::Release(..) => After::More,
                    Next::Park(due) => After::Park(due),
                };
                Next::Release(release, period_us, after)
            }
            None => Next::Park(earliest),
        }
    }

    #[test]
    fn the_one_key_walk_answers_as_the_walk_before_it() {
        let mut seed = 0xD1B5_4A32_D192_ED03u64;
        let (mut releases, mut parks) = (0, 0);
        // Releases after which another is due, and job's last releases (after which none is).
        let (mut more, mut last) = (0, 0);
        for round in 0..400u64 {
            let at = 1 + round * 613;
            for levels in LEVEL_SETS {
                let ranks = Ranks::of(levels);
                let table = random_table(&mut seed, at);
                let (mut old, mut new) = (table.clone(), table);
                for now in [at, at + 50, at + 7_000] {
                    // Every step of a job and the park that ends it, answer for answer.
                    for _ in 0..=new.publishers().len() {
                        let expected = take_next_before(&mut old, ranks, now);
                        let got = take_next(&mut new, ranks, now);
                        assert_eq!(got, expected, "levels {levels:?} at {now}");
                        assert_eq!(new.publishers(), old.publishers());
                        match got {
                            Next::Release(_, _, after) => {
                                releases += 1;
                                match after {
                                    After::More => more += 1,
                                    After::Park(_) => last += 1,
                                }
                            }
                            Next::Park(_) => {
                                parks += 1;
                                break;
                            }
                        }
                    }
                }
            }
        }
        assert!(
            releases > 1_000 && parks > 1_000 && more > 500 && last > 500,
            "{releases} releases ({more} with more due, {last} last), {parks} parks"
        );
    }

    #[test]
    fn every_board_table_is_in_topic_byte_order() {
        // take_next breaks a tie of rank and due time by the table's order, which must be the
        // topic bytes' (take_next_release's and the protocol's order).
        for board in amiro_can::Board::ALL {
            let handler = SensorDataHandler::new(board);
            let bytes: Vec<u8> = handler
                .publishers()
                .iter()
                .map(|p| p.topic().byte())
                .collect();
            assert!(!bytes.is_empty(), "{board:?}");
            assert!(
                bytes.windows(2).all(|w| w[0] < w[1]),
                "{board:?}: {bytes:?}"
            );
        }
    }

    #[test]
    fn equal_due_times_release_in_topic_byte_order() {
        let mut handler = SensorDataHandler::new(Board::DiWheelDrive);
        // Every topic one-shot at the same instant and level: released in the table's order.
        let topics: Vec<Topic> = handler.publishers().iter().map(|p| p.topic()).collect();
        for &topic in topics.iter().rev() {
            let id = CanId::new(Kind::Command, Priority::Medium, topic.byte()).raw();
            let _ = handler.on_frame(100, id, &[2]);
        }
        let got = one_walk(&mut handler, &[Priority::Medium], 5_000);
        let order: Vec<Topic> = got.iter().map(|r| r.topic).collect();
        assert_eq!(order, topics);
    }

    #[test]
    fn a_fresh_table_has_nothing_due_at_any_level() {
        // serve_level parks on the wake channel alone at first, without a walk: a fresh table must
        // have nothing due, so that only a command (which wakes the levels it gives a due time)
        // starts a release.
        for board in amiro_can::Board::ALL {
            let handler = SensorDataHandler::new(board);
            for levels in LEVEL_SETS {
                assert_eq!(next_due(&handler, Ranks::of(levels)), None, "{board:?}");
            }
            assert!(handler
                .publishers()
                .iter()
                .all(|p| p.next_due_us().is_none()));
        }
    }

    #[test]
    fn ranks_keep_each_level_first_place() {
        let ranks = Ranks::of(&[Priority::Medium, Priority::Urgent, Priority::Medium]);
        assert_eq!(ranks.of_level(Priority::Medium), Some(0));
        assert_eq!(ranks.of_level(Priority::Urgent), Some(1));
        assert_eq!(ranks.of_level(Priority::High), None);
        assert_eq!(ranks.of_level(Priority::Low), None);
        assert_eq!(Ranks::of(&[]).of_level(Priority::Low), None);
    }
}
