//! The sensor-data handler of one board: turns the commands heard on the CAN bus into the board's
//! publisher table, and tells the firmware's per-CAN-priority publisher tasks which topics are due.
//!
//! The handler is pure bookkeeping: it never samples a sensor or touches the bus. The firmware
//! feeds it received frames ([`SensorDataHandler::on_frame`]) and asks it, once per CAN priority
//! level, when to wake up next ([`SensorDataHandler::next_due`]) and what is due now
//! ([`SensorDataHandler::take_due`]). All times are microseconds of one monotonic
//! [`Clock`](crate::clock::Clock); the caller passes `now_us` so the handler runs under a fake clock
//! in tests. The timing rules are written down in `docs/handler.md`.

use core::fmt;
use core::num::NonZeroU32;

use amiro_can::{
    decode_command, AdmissionPolicy, Board, CanId, Command, DecodeError, Kind, Priority,
    SensorCommand, SensorMode, Topic,
};

/// Room in the publisher table: the most topics any board publishes (DiWheelDrive's nine, its
/// diagnostics included), computed when the crate compiles so no board can outgrow it.
pub const MAX_PUBLISHERS: usize = {
    let mut most = 0;
    let mut i = 0;
    while i < Board::ALL.len() {
        let owned = sensor_topics_of(Board::ALL[i]);
        if owned > most {
            most = owned;
        }
        i += 1;
    }
    most
};

/// How many sensor topics `board` owns.
const fn sensor_topics_of(board: Board) -> usize {
    let mut count = 0;
    let mut i = 0;
    while i < Topic::ALL.len() {
        let topic = Topic::ALL[i];
        if topic.is_sensor() && topic.board() as u8 == board as u8 {
            count += 1;
        }
        i += 1;
    }
    count
}

/// Number of reasons a command can be rejected for (one counter each).
pub const REJECT_REASONS: usize = DecodeError::KINDS.len();

/// The number of CAN priority levels, and so of publisher tasks in a firmware.
pub const LEVELS: usize = Priority::ALL.len();

/// What a publisher slot is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PublisherState {
    /// Not publishing (mode 0, or never started).
    Stopped,
    /// Publishing every period (mode 1).
    Publishing,
    /// One sample requested (mode 2) and not yet taken; the slot stops once it is taken.
    OnceRequested,
}

/// One row of the publisher table: a sensor topic this board owns and how it is published.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Publisher {
    next_due_us: u64,
    period_us: NonZeroU32,
    missed: u32,
    topic: Topic,
    priority: Priority,
    state: PublisherState,
}

impl Publisher {
    fn idle(topic: Topic) -> Self {
        Self {
            next_due_us: 0,
            period_us: period_from_micros(u64::from(topic.default_period_us())),
            missed: 0,
            topic,
            priority: Priority::Low,
            state: PublisherState::Stopped,
        }
    }

    /// The sensor topic this slot publishes.
    pub fn topic(&self) -> Topic {
        self.topic
    }

    /// What the slot is doing.
    pub fn state(&self) -> PublisherState {
        self.state
    }

    /// True while a periodic publisher (mode 1) runs.
    pub fn is_publishing(&self) -> bool {
        self.state == PublisherState::Publishing
    }

    /// The CAN priority its samples are sent with, which is also the level whose task serves it.
    /// Kept when the publisher stops, so it reads as the last commanded priority.
    pub fn priority(&self) -> Priority {
        self.priority
    }

    /// The publishing period in microseconds. Until a mode-1 command sets one it reads as the
    /// topic's natural period from the protocol table (a mode-1 command without a sample time means
    /// 50 ms, as the protocol fixes; the table value is only informative).
    pub fn period_us(&self) -> u32 {
        self.period_us.get()
    }

    /// When the next sample is due, or `None` while stopped.
    pub fn next_due_us(&self) -> Option<u64> {
        match self.state {
            PublisherState::Stopped => None,
            PublisherState::Publishing | PublisherState::OnceRequested => Some(self.next_due_us),
        }
    }

    /// Releases of this topic skipped because the publisher fell a full period behind (since boot).
    pub fn missed_releases(&self) -> u32 {
        self.missed
    }

    fn is_due_at(&self, level: Priority, now_us: u64) -> bool {
        self.state != PublisherState::Stopped
            && self.priority == level
            && self.next_due_us <= now_us
    }

    /// Takes the due release and schedules the next one. Only called when `is_due_at` holds.
    fn release(&mut self, now_us: u64) -> Release {
        let once = self.state == PublisherState::OnceRequested;
        if once {
            self.state = PublisherState::Stopped;
            return Release {
                topic: self.topic,
                priority: self.priority,
                release_us: self.next_due_us,
                once: true,
                missed: 0,
                late_us: 0,
            };
        }
        let behind = now_us.saturating_sub(self.next_due_us);
        // Releases after the due one that have also passed: serving them all now would be a burst
        // of identical samples, so only the latest is served and the older ones count as missed.
        let skipped = crate::clock::div_us(behind, self.period_us.get());
        let period = u64::from(self.period_us.get());
        let release_us = self
            .next_due_us
            .saturating_add(skipped.saturating_mul(period));
        let late_us = if skipped > 0 {
            // The oldest skipped release's deadline was the release after it.
            now_us.saturating_sub(self.next_due_us.saturating_add(period))
        } else {
            0
        };
        let missed = u32::try_from(skipped).unwrap_or(u32::MAX);
        self.missed = self.missed.saturating_add(missed);
        // Drift-free: the next release is anchored on the release grid, never on `now`.
        self.next_due_us = release_us.saturating_add(period);
        Release {
            topic: self.topic,
            priority: self.priority,
            release_us,
            once: false,
            missed,
            late_us,
        }
    }
}

/// How late a frame queued at `queued_us` is for its release's `deadline_us` (`None`: in time, or a
/// one-shot, which has no deadline). The publisher loop counts and traces a late frame as a
/// deadline miss.
pub fn late_by(queued_us: u64, deadline_us: Option<u64>) -> Option<u32> {
    let deadline = deadline_us.filter(|d| queued_us > *d)?;
    Some(u32::try_from(queued_us - deadline).unwrap_or(u32::MAX))
}

/// Clamps a period to the range the table stores: at least 1 µs, at most `u32::MAX` µs (the
/// decoder already rejects zero and anything above `amiro_can::MAX_PERIOD_US`).
fn period_from_micros(period_us: u64) -> NonZeroU32 {
    let clamped = u32::try_from(period_us).unwrap_or(u32::MAX);
    NonZeroU32::new(clamped).unwrap_or(NonZeroU32::MIN)
}

/// One sample a publisher task must take and send now.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Release {
    /// The topic to sample.
    pub topic: Topic,
    /// The CAN priority to send the sample with (the level that served it).
    pub priority: Priority,
    /// The release this sample serves: a point of the publisher's period grid, or the time a
    /// one-shot was requested.
    pub release_us: u64,
    /// True for a mode-2 one-shot; the publisher is stopped now.
    pub once: bool,
    /// Earlier releases skipped because the publisher was a full period or more behind
    /// (each one a deadline miss); 0 normally.
    pub missed: u32,
    /// When `missed > 0`: how late the oldest skipped release is past its deadline (the release
    /// after it), in microseconds.
    pub late_us: u64,
}

/// A set of CAN priority levels: which publisher tasks must re-read their next due time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Levels(u8);

impl Levels {
    /// No level.
    pub const NONE: Levels = Levels(0);

    /// This set with `level` added.
    #[must_use]
    pub fn with(self, level: Priority) -> Levels {
        Levels(self.0 | (1 << level as u8))
    }

    /// Whether `level` is in the set.
    pub fn contains(self, level: Priority) -> bool {
        self.0 & (1 << level as u8) != 0
    }

    /// True when no level is in the set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The levels in the set, most urgent first.
    pub fn iter(self) -> impl Iterator<Item = Priority> {
        Priority::ALL
            .into_iter()
            .filter(move |level| self.contains(*level))
    }
}

/// Why a frame was not for this board.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Ignored {
    /// A command for a topic another board owns (every board hears every frame).
    OtherBoard(Topic),
    /// A sensor-data frame (C/S bit set): samples are for the operator, not for a handler.
    SensorData,
}

/// What the handler did with a frame it accepted or ignored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// A command for one of this board's sensor topics was applied to the publisher table.
    Sensor {
        /// The decoded command.
        command: SensorCommand,
        /// The levels whose next due time may have changed: the firmware wakes those tasks so
        /// they re-read [`SensorDataHandler::next_due`] (a one-shot or a new publisher is due now).
        wake: Levels,
    },
    /// A command for this board that the firmware acts on, as decoded: a motor command (hand it
    /// to the motor controller), an LED command (to the LED driver), an admission policy (the
    /// handler keeps it, [`SensorDataHandler::admission_policy`]; the firmware's admission check
    /// reads it there) or a shutdown (PowerManagement only; the other boards ignore it and follow
    /// SYS_PD_N: the firmware starts the robot's shutdown in its mode). Never a sensor command: those
    /// are applied, [`Outcome::Sensor`].
    Command(Command),
    /// Not for this board; counted, nothing changed.
    Ignored(Ignored),
}

/// A command frame the handler refused: it was malformed, and the table is untouched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rejection {
    /// Why the protocol decoder refused it.
    pub reason: DecodeError,
}

impl Rejection {
    /// Why the protocol decoder refused the frame.
    pub fn reason(&self) -> DecodeError {
        self.reason
    }
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "command rejected: {}", self.reason)
    }
}

/// What the handler has seen since boot. Counters saturate instead of wrapping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HandlerCounters {
    /// Commands applied or handed to a sink (sensor, motor, LED).
    pub accepted: u32,
    /// Rejected commands, one counter per [`DecodeError::kind_index`].
    pub rejected: [u32; REJECT_REASONS],
    /// Commands for topics another board owns.
    pub ignored_other_board: u32,
    /// Sensor-data frames heard on the bus.
    pub ignored_sensor_data: u32,
    /// Samples released to the publisher tasks (periodic and one-shot).
    pub releases: u32,
    /// Periodic releases skipped because a publisher fell a full period behind.
    pub deadline_misses: u32,
}

impl HandlerCounters {
    const ZERO: HandlerCounters = HandlerCounters {
        accepted: 0,
        rejected: [0; REJECT_REASONS],
        ignored_other_board: 0,
        ignored_sensor_data: 0,
        releases: 0,
        deadline_misses: 0,
    };

    /// How many commands were rejected for `reason`'s kind.
    pub fn rejected_for(&self, reason: DecodeError) -> u32 {
        self.rejected.get(reason.kind_index()).copied().unwrap_or(0)
    }

    /// How many commands were rejected, whatever the reason.
    pub fn rejected_total(&self) -> u32 {
        self.rejected
            .iter()
            .fold(0u32, |sum, count| sum.saturating_add(*count))
    }

    /// How many frames were ignored, whatever the reason.
    pub fn ignored_total(&self) -> u32 {
        self.ignored_other_board
            .saturating_add(self.ignored_sensor_data)
    }
}

impl Default for HandlerCounters {
    fn default() -> Self {
        Self::ZERO
    }
}

/// The sensor-data handler of one board: its publisher table and its command counters.
#[derive(Clone, Debug)]
pub struct SensorDataHandler {
    board: Board,
    publishers: heapless::Vec<Publisher, MAX_PUBLISHERS, u8>,
    counters: HandlerCounters,
    policy: AdmissionPolicy,
}

impl SensorDataHandler {
    /// A handler for `board` with one stopped publisher per sensor topic the board owns, in the
    /// order of the protocol's topic table.
    pub fn new(board: Board) -> Self {
        let mut publishers = heapless::Vec::new();
        for topic in Topic::ALL
            .into_iter()
            .filter(|topic| topic.board() == board && topic.is_sensor())
        {
            // Cannot fail: MAX_PUBLISHERS is the largest count of this very filter over all boards.
            let _ = publishers.push(Publisher::idle(topic));
        }
        Self {
            board,
            publishers,
            counters: HandlerCounters::ZERO,
            policy: AdmissionPolicy::Refuse,
        }
    }

    /// The admission policy the last policy command set ([`AdmissionPolicy::Refuse`] after reset).
    pub fn admission_policy(&self) -> AdmissionPolicy {
        self.policy
    }

    /// The board this handler serves.
    pub fn board(&self) -> Board {
        self.board
    }

    /// The publisher table, one row per sensor topic of the board.
    pub fn publishers(&self) -> &[Publisher] {
        &self.publishers
    }

    /// The row of `topic`, or `None` if this board does not publish it.
    pub fn publisher(&self, topic: Topic) -> Option<&Publisher> {
        self.publishers.iter().find(|slot| slot.topic == topic)
    }

    /// What the handler has seen since boot.
    pub fn counters(&self) -> &HandlerCounters {
        &self.counters
    }

    /// Handles one frame heard on the bus at `now_us`.
    ///
    /// Frames for other boards and sensor-data frames are [`Outcome::Ignored`]; malformed commands
    /// are rejected with the decoder's reason and change nothing but their counter.
    pub fn on_frame(&mut self, now_us: u64, id: u16, data: &[u8]) -> Result<Outcome, Rejection> {
        self.on_command(now_us, id, decode_command(id, data))
    }

    /// [`SensorDataHandler::on_frame`] for a frame this handler has already handled and counted once: applied
    /// again, counted no more. The firmware applies a stop as it arrives (so it takes effect at once) and again
    /// in the admission task's order (in case a request for the same topic was still waiting there); counting
    /// both made the diagnostics' accepted count one higher than the commands heard for every stop.
    pub fn on_frame_again(
        &mut self,
        now_us: u64,
        id: u16,
        data: &[u8],
    ) -> Result<Outcome, Rejection> {
        let counted = self.counters;
        let outcome = self.on_frame(now_us, id, data);
        self.counters = counted;
        outcome
    }

    /// [`SensorDataHandler::on_frame`] for a frame its caller has already decoded: `decoded` is
    /// `decode_command(id, data)` of the frame heard (the firmware's command handler decodes each
    /// frame once, to route it). Whether the frame is this board's business is decided from the
    /// identifier first, so a malformed command for another board is ignored, not rejected.
    pub fn on_command(
        &mut self,
        now_us: u64,
        id: u16,
        decoded: Result<Command, DecodeError>,
    ) -> Result<Outcome, Rejection> {
        if let Some(ignored) = self.count_not_for_us(id) {
            return Ok(Outcome::Ignored(ignored));
        }
        self.on_decoded(now_us, decoded)
    }

    /// [`SensorDataHandler::not_for_us`], counted.
    #[inline]
    fn count_not_for_us(&mut self, id: u16) -> Option<Ignored> {
        let ignored = self.not_for_us(id)?;
        let count = match ignored {
            Ignored::OtherBoard(_) => &mut self.counters.ignored_other_board,
            Ignored::SensorData => &mut self.counters.ignored_sensor_data,
        };
        *count = count.saturating_add(1);
        Some(ignored)
    }

    /// The rest of [`SensorDataHandler::on_frame`], once the frame is known to be a command this
    /// board may own: the decoder's verdict applied and counted.
    #[inline]
    fn on_decoded(
        &mut self,
        now_us: u64,
        decoded: Result<Command, DecodeError>,
    ) -> Result<Outcome, Rejection> {
        let command = match decoded {
            Ok(command) => command,
            Err(reason) => {
                if let Some(count) = self.counters.rejected.get_mut(reason.kind_index()) {
                    *count = count.saturating_add(1);
                }
                return Err(Rejection { reason });
            }
        };
        let outcome = match command {
            Command::Sensor(command) => match self.apply(now_us, command) {
                Some(wake) => Outcome::Sensor { command, wake },
                None => Outcome::Ignored(Ignored::OtherBoard(command.topic)),
            },
            Command::Motor { .. } | Command::Led { .. } => Outcome::Command(command),
            // `not_for_us` already ignored another board's diagnostics topic and, on every board
            // but PowerManagement, the shutdown topic; the checks here keep that true by themselves.
            Command::Policy { board, policy, .. } if board == self.board => {
                self.policy = policy;
                Outcome::Command(command)
            }
            Command::Policy { board, .. } => {
                Outcome::Ignored(Ignored::OtherBoard(board.diagnostics_topic()))
            }
            Command::Shutdown { .. } if Topic::Shutdown.board() == self.board => {
                Outcome::Command(command)
            }
            Command::Shutdown { .. } => Outcome::Ignored(Ignored::OtherBoard(Topic::Shutdown)),
        };
        match outcome {
            Outcome::Ignored(_) => {
                self.counters.ignored_other_board =
                    self.counters.ignored_other_board.saturating_add(1);
            }
            _ => self.counters.accepted = self.counters.accepted.saturating_add(1),
        }
        Ok(outcome)
    }

    /// Decides from the identifier alone whether a frame is someone else's business, so a
    /// malformed command for another board is ignored here rather than rejected (and traced as
    /// an error) on every board that hears it.
    fn not_for_us(&self, id: u16) -> Option<Ignored> {
        // An identifier out of range falls through to the decoder, which names the error.
        let can_id = CanId::try_from(id).ok()?;
        if can_id.kind() == Kind::Sensor {
            return Some(Ignored::SensorData);
        }
        let topic = Topic::try_from(can_id.topic_byte()).ok()?;
        (topic.board() != self.board).then_some(Ignored::OtherBoard(topic))
    }

    /// Applies a decoded sensor command; `None` if the topic has no row on this board.
    fn apply(&mut self, now_us: u64, command: SensorCommand) -> Option<Levels> {
        let slot = self
            .publishers
            .iter_mut()
            .find(|slot| slot.topic == command.topic)?;
        let mut wake = Levels::NONE;
        if slot.state != PublisherState::Stopped {
            wake = wake.with(slot.priority);
        }
        match command.mode {
            SensorMode::Stop => {
                // Also cancels a one-shot not yet taken: "stop" means no more samples.
                slot.state = PublisherState::Stopped;
            }
            SensorMode::Publish(sample_time) => {
                let period = period_from_micros(sample_time.as_micros());
                slot.next_due_us = match slot.state {
                    // An update keeps the running phase unless the new period asks for a sample
                    // sooner: no burst, no gap longer than the new period, and re-sending the
                    // same command changes nothing.
                    PublisherState::Publishing => slot
                        .next_due_us
                        .min(now_us.saturating_add(u64::from(period.get()))),
                    // A start releases its first sample at once (a pending one-shot is served by
                    // that same first sample).
                    PublisherState::Stopped | PublisherState::OnceRequested => now_us,
                };
                slot.period_us = period;
                slot.priority = command.priority;
                slot.state = PublisherState::Publishing;
            }
            SensorMode::Once => {
                // A second request before the first is served still yields one sample.
                slot.next_due_us = match slot.state {
                    PublisherState::OnceRequested => slot.next_due_us.min(now_us),
                    PublisherState::Stopped | PublisherState::Publishing => now_us,
                };
                slot.priority = command.priority;
                slot.state = PublisherState::OnceRequested;
            }
        }
        if slot.state != PublisherState::Stopped {
            wake = wake.with(slot.priority);
        }
        Some(wake)
    }

    /// Stops every publisher and cancels pending one-shots (shutdown request); returns the levels
    /// that had work, so the firmware can let their tasks go idle.
    pub fn stop_all(&mut self) -> Levels {
        let mut wake = Levels::NONE;
        for slot in self.publishers.iter_mut() {
            if slot.state != PublisherState::Stopped {
                wake = wake.with(slot.priority);
                slot.state = PublisherState::Stopped;
            }
        }
        wake
    }

    /// The earliest due time among the running publishers and pending one-shots at `level`, or
    /// `None` if that level has nothing to do. It may lie in the past: the task is behind.
    pub fn next_due(&self, level: Priority) -> Option<u64> {
        self.publishers
            .iter()
            .filter(|slot| slot.state != PublisherState::Stopped && slot.priority == level)
            .map(|slot| slot.next_due_us)
            .min()
    }

    /// The earliest due time over all levels, or `None` if nothing is published.
    pub fn next_due_any(&self) -> Option<u64> {
        self.publishers
            .iter()
            .filter_map(Publisher::next_due_us)
            .min()
    }

    /// Hands every topic of `level` that is due at `now_us` to `out` as `(topic, release_us)`, once
    /// each, and schedules the next release of each. Returns how many were released.
    ///
    /// Order: earliest release first; ties go to the lower topic byte (the lower CAN identifier,
    /// which would win arbitration anyway). `out` runs while the caller holds the handler; a
    /// firmware that samples slow sensors, or wants to trace deadline misses, should use
    /// [`take_due_releases`](Self::take_due_releases) and sample after releasing its lock.
    pub fn take_due(
        &mut self,
        level: Priority,
        now_us: u64,
        mut out: impl FnMut(Topic, u64),
    ) -> usize {
        self.release_due(level, now_us, |release| {
            out(release.topic, release.release_us)
        })
    }

    /// Like [`take_due`](Self::take_due), returning the full [`Release`] records (priority,
    /// one-shot flag, deadline misses) as a bounded list.
    pub fn take_due_releases(
        &mut self,
        level: Priority,
        now_us: u64,
    ) -> heapless::Vec<Release, MAX_PUBLISHERS> {
        let mut releases = heapless::Vec::new();
        self.release_due(level, now_us, |release| {
            // At most one release per row, so the list never overflows.
            let _ = releases.push(release);
        });
        releases
    }

    /// The earliest release of `level` due at `now_us` (ties to the lower topic byte), taken and its
    /// next one scheduled; `None` when nothing of `level` is due. Taking releases one at a time
    /// until `None` hands out what [`take_due_releases`](Self::take_due_releases) does at once, in
    /// its order (each take makes its row not due at `now_us`): the publisher task takes one,
    /// samples it, and takes the next, so each pass of its loop is one release (the
    /// execution-time analysis charges a job per release, docs/analysis.md "One topic's job").
    pub fn take_next_release(&mut self, level: Priority, now_us: u64) -> Option<Release> {
        let slot = self
            .publishers
            .iter_mut()
            .filter(|slot| slot.is_due_at(level, now_us))
            .min_by_key(|slot| (slot.next_due_us, slot.topic as u8))?;
        let release = slot.release(now_us);
        Some(self.count(release))
    }

    /// The release of row `index` of [`publishers`](Self::publishers) if that row is due at
    /// `now_us` (running or a pending one-shot, its due time passed), taken and its next one
    /// scheduled as [`take_next_release`](Self::take_next_release) takes it; `None` otherwise.
    /// For a caller that chose the row in its own walk of the table (the publisher task's one walk
    /// for all its levels, `amiro_firmware::publisher_walk::take_next`), so that choosing and taking
    /// a release is one walk, not two.
    pub fn take_release_of_row(&mut self, index: usize, now_us: u64) -> Option<Release> {
        let slot = self
            .publishers
            .get_mut(index)
            .filter(|slot| slot.is_due_at(slot.priority, now_us))?;
        let release = slot.release(now_us);
        Some(self.count(release))
    }

    /// Counts a release taken.
    fn count(&mut self, release: Release) -> Release {
        self.counters.releases = self.counters.releases.saturating_add(1);
        self.counters.deadline_misses =
            self.counters.deadline_misses.saturating_add(release.missed);
        release
    }

    fn release_due(&mut self, level: Priority, now_us: u64, mut out: impl FnMut(Release)) -> usize {
        let mut released: usize = 0;
        // Each pass makes the chosen row not due (its next release lies after `now_us`, or it
        // stopped), so the table size bounds the loop.
        for _ in 0..MAX_PUBLISHERS {
            let Some(release) = self.take_next_release(level, now_us) else {
                break;
            };
            released = released.saturating_add(1);
            out(release);
        }
        released
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_board_gets_one_row_per_sensor_topic() {
        for board in Board::ALL {
            let owned: std::vec::Vec<Topic> = amiro_can::TOPICS
                .iter()
                .filter(|info| info.board == board && info.is_sensor)
                .map(|info| info.topic)
                .collect();
            assert!(
                owned.len() <= MAX_PUBLISHERS,
                "{board} owns {} sensor topics",
                owned.len()
            );
            let handler = SensorDataHandler::new(board);
            let rows: std::vec::Vec<Topic> =
                handler.publishers().iter().map(Publisher::topic).collect();
            assert_eq!(rows, owned, "{board}");
        }
        assert_eq!(
            MAX_PUBLISHERS, 9,
            "DiWheelDrive publishes eight sensor topics and its diagnostics"
        );
    }

    #[test]
    fn levels_set_operations() {
        let set = Levels::NONE.with(Priority::Low).with(Priority::Urgent);
        assert!(set.contains(Priority::Urgent) && set.contains(Priority::Low));
        assert!(!set.contains(Priority::High) && !set.is_empty());
        let listed: std::vec::Vec<Priority> = set.iter().collect();
        assert_eq!(listed, [Priority::Urgent, Priority::Low]);
        assert!(Levels::NONE.is_empty());
    }

    #[test]
    fn periods_are_clamped_into_the_table_range() {
        assert_eq!(period_from_micros(0).get(), 1);
        assert_eq!(period_from_micros(900).get(), 900);
        assert_eq!(period_from_micros(u64::MAX).get(), u32::MAX);
    }

    #[test]
    fn handler_is_small() {
        // The QEMU board has little RAM; a handler plus a 16-frame queue must stay well under 1 KiB.
        let size = core::mem::size_of::<SensorDataHandler>();
        assert!(size <= 384, "SensorDataHandler is {size} bytes");
    }
}
