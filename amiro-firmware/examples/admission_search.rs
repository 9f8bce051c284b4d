//! A search for the on-chip admission check's costliest step (issue 20): random command sequences (publish
//! requests of every topic of the robot at every level and a spread of periods, stops, one-shots, and with
//! `policies` policy changes), each replayed through a board's [`Admission`] on the host step by step, as the admission
//! task runs them ([`Admission::replay`]: the preparation steps, the decision, the refresh steps after a stop; each
//! analyses at most one board and the bus), then hill-climbed by mutating single
//! commands of the best sequence. The objective is a step's fixed-point iterations (what the host can count the
//! same as the chip); the instructions the chip spends on the winner are measured by replaying its `candump -l`
//! log in QEMU (scenario `admission-search`, which checks them against the admission task's budget).
//!
//! `cargo run --release -p amiro-firmware --example admission_search -- [SEED] [ROUNDS] [policies] > admission-search.log`
use amiro_firmware::admission::{Admission, State};
use schedule_analysis::{admission_host, rng::Rng};

/// Every sensor topic of the robot: DiWheelDrive's nine, PowerManagement's three, LightRing's one.
const TOPICS: [u8; 13] = [
    0x01, 0x02, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x1A, 0x1B, 0x1E, 0x1F, 0x1C,
];
/// The boards' diagnostics topics (where a policy command goes).
const DIAGNOSTICS: [u8; 3] = [0x1A, 0x1B, 0x1C];
/// Periods tried: (value, unit byte: 0 ms, 1 s, 2 µs).
const PERIODS: [(u16, u8); 14] = [
    (1, 2),
    (100, 2),
    (400, 2),
    (700, 2),
    (900, 2),
    (1, 0),
    (2, 0),
    (5, 0),
    (10, 0),
    (20, 0),
    (50, 0),
    (100, 0),
    (500, 0),
    (1, 1),
];
/// Commands per sequence (the protocol's 13 publishers fit several times over).
const LENGTH: usize = 40;

#[derive(Clone, Copy, Debug)]
struct Command {
    id: u16,
    data: [u8; 4],
    len: usize,
}

fn random_command(rng: &mut Rng, policies: bool) -> Command {
    let level = rng.below(4) as u16;
    let topic = rng.pick(&TOPICS) as u16;
    match rng.below(if policies { 10 } else { 9 }) {
        // Mostly publish requests: they are what the check analyses.
        0..=5 => {
            let (value, unit) = rng.pick(&PERIODS);
            let [lo, hi] = value.to_le_bytes();
            Command {
                id: level << 8 | topic,
                data: [1, lo, hi, unit],
                len: 4,
            }
        }
        6 | 7 => Command {
            id: level << 8 | topic,
            data: [0, 0, 0, 0],
            len: 1,
        },
        8 => Command {
            id: level << 8 | topic,
            data: [2, 0, 0, 0],
            len: 1,
        },
        _ => Command {
            id: rng.pick(&DIAGNOSTICS) as u16,
            data: [3, rng.below(2) as u8, 0, 0],
            len: 2,
        },
    }
}

/// The costliest step of `commands` replayed from a fresh state: (iterations, index of the command, whether it
/// was the refresh after it).
fn worst_step(
    table: &schedule_analysis::admission::RobotTable<'_>,
    commands: &[Command],
) -> (u64, usize, bool) {
    let mut state = Box::new(State::<48, 32>::new());
    let mut admission = Admission::new(table, amiro_can::Board::DiWheelDrive, &mut state);
    admission.prepare();
    let mut worst = (0, 0, false);
    for (i, c) in commands.iter().enumerate() {
        let mut steps = 0;
        let _ = admission.replay(c.id, &c.data[..c.len], |iterations| {
            worst = worst.max((iterations, i, steps > 0));
            steps += 1;
        });
    }
    worst
}

fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(20, |s| s.parse().expect("a seed"));
    let rounds: usize = args.next().map_or(3000, |s| s.parse().expect("rounds"));
    // Policy changes only when asked (`policies`); scenario admission-search's sequence was searched without them.
    let policies = args.next().as_deref() == Some("policies");
    let robot = admission_host::lower_robot(&root).expect("table");
    robot.with_table(|table| {
        let mut rng = Rng::new(seed.max(1));
        let mut best: Vec<Command> = (0..LENGTH).map(|_| random_command(&mut rng, policies)).collect();
        let mut best_cost = worst_step(table, &best);
        // A step analyses at most one board and the bus, each within the check's iteration cap
        // (schedule_analysis::admission::DECISION_ITERATIONS): a sequence whose costliest step reaches both caps
        // cannot be beaten (a candidate replaces the best only when it takes more), so the search stops there.
        let most = 2 * schedule_analysis::admission::DECISION_ITERATIONS;
        let mut run = 0;
        for round in 0..rounds {
            if best_cost.0 >= most {
                break;
            }
            run = round + 1;
            // Half the rounds a fresh random sequence, half a mutation of the best one.
            let candidate: Vec<Command> = if round % 2 == 0 {
                (0..LENGTH).map(|_| random_command(&mut rng, policies)).collect()
            } else {
                let mut c = best.clone();
                for _ in 0..1 + rng.below(3) {
                    let at = rng.index(LENGTH);
                    c[at] = random_command(&mut rng, policies);
                }
                c
            };
            let cost = worst_step(table, &candidate);
            if cost.0 > best_cost.0 {
                best = candidate;
                best_cost = cost;
                eprintln!(
                    "round {round}: {} iterations at command {}{}",
                    cost.0,
                    cost.1,
                    if cost.2 { " (its refresh)" } else { "" }
                );
            }
        }
        // The winner, cut after its costliest step, as a stimulus log (one command per 45 ms: the admission
        // task's sustained pace, so none waits for the pacing or finds the queue full).
        let end = best_cost.1 + 1;
        println!(
            "# Found by amiro-firmware/examples/admission_search.rs (seed {seed}, {run} of {rounds} rounds{}): the command sequence whose",
            if run < rounds { ", stopped at the most a step can take" } else { "" }
        );
        println!(
            "# costliest admission step took the most fixed-point iterations on the host ({} at command {}{}).",
            best_cost.0,
            best_cost.1 + 1,
            if best_cost.2 { ", its refresh step" } else { "" }
        );
        println!(
            "# Replayed in QEMU by scenario admission-search: every step within the admission task's budget per step."
        );
        println!("# duration: {}ms", end * 45 + 60);
        for (i, c) in best[..end].iter().enumerate() {
            let data: String = c.data[..c.len].iter().map(|b| format!("{b:02X}")).collect();
            let at = amiro_can::candump::Timestamp::from_micros((5_000 + i * 45_000) as u64);
            println!("({at}) can0 {:03X}#{data}", c.id);
        }
    });
}
