//! A search for the on-chip admission check's costliest step (issue 20): the search of
//! [`amiro_firmware::admission_search`] on the tables `AMIRO_REVISION` names, its winner printed as a stimulus log
//! for scenario `admission-search` (which replays it in QEMU and checks the instructions against the admission
//! task's budget). `cargo xtask admission-search` runs this and compares the winner with the stored logs.
//!
//! `cargo run --release -p amiro-firmware --example admission_search -- [SEED] [ROUNDS] [policies] > admission-search.log`
use std::process::ExitCode;

use amiro_firmware::admission_search;
use schedule_analysis::admission_host;

fn main() -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut args = std::env::args().skip(1);
    let (Ok(seed), Ok(rounds)) = (
        args.next().map_or(Ok(20), |s| s.parse::<u64>()),
        args.next().map_or(Ok(3000), |s| s.parse::<usize>()),
    ) else {
        eprintln!("usage: admission_search [SEED] [ROUNDS] [policies]");
        return ExitCode::FAILURE;
    };
    // Policy changes only when asked (`policies`).
    let policies = args.next().as_deref() == Some("policies");
    let robot = match admission_host::lower_robot(&root) {
        Ok(robot) => robot,
        Err(e) => {
            eprintln!("the admission table: {e}");
            return ExitCode::FAILURE;
        }
    };
    let found = robot.with_table(|table| {
        admission_search::search(table, seed, rounds, policies, |round, cost| {
            eprintln!("round {round}: {cost}");
        })
    });
    print!(
        "{}",
        found
            .to_log("amiro-firmware/examples/admission_search.rs")
            .render()
    );
    ExitCode::SUCCESS
}
