//! The traced QEMU model (`Firmware::Qemu`) scales a board's budgets by its timing file's `trace.qemu.budget_scale`
//! (QEMU's CPU speed against the chip's), but not the stated bus waits of a budget bounded from the machine code:
//! a wait is the bus's time, and QEMU's simulated devices answer at once (docs/bench.md, "The traced QEMU model").

use std::path::PathBuf;

use schedule_analysis::scenario::{self, scaled_cpu, BudgetFrom, Built, Firmware};

mod common;

fn root() -> PathBuf {
    common::workspace()
}

#[test]
fn a_budget_of_cpu_c_and_waits_w_scaled_by_f_is_c_f_plus_w() {
    // Known answers: CPU 9 460.3 µs and 25 442.4 µs of waits (PowerManagement's ring, 2026-12-06) at ×2.
    let (c, w) = (9_460.3, 25_442.4);
    assert!((scaled_cpu(c + w, w, 2.0) - (2.0 * c + w)).abs() < 1e-6);
    assert_eq!(scaled_cpu(100.0, 0.0, 2.0), 200.0);
    assert_eq!(scaled_cpu(100.0, 40.0, 1.0), 100.0);
    // Waits are never more than the budget (a best case below the waits stays as it is) nor negative.
    assert_eq!(scaled_cpu(30.0, 2_029.5, 2.0), 30.0);
    assert_eq!(scaled_cpu(30.0, -5.0, 2.0), 60.0);
}

/// The wcet of `board`'s job whose budget is row `row`, and that row's bound and its waits.
fn job(built: &Built, board: &str, row: &str) -> (f64, f64, f64) {
    let budgets = built
        .budgets
        .iter()
        .find(|b| b.board == board)
        .expect(board);
    let Some(BudgetFrom::Bound {
        us, bus_wait_us, ..
    }) = budgets.rows.get(row)
    else {
        panic!("{board}: {row} is not bounded: {:?}", budgets.rows.get(row));
    };
    let model = built
        .model
        .boards
        .iter()
        .find(|b| b.name == board)
        .expect(board);
    let task = model
        .tasks
        .iter()
        .find(|t| budgets.row_of_job(&t.name) == Some(row))
        .unwrap_or_else(|| panic!("{board}: no job with row {row}"));
    (task.wcet_us, *us, *bus_wait_us)
}

#[test]
fn the_qemu_model_scales_powermanagements_cpu_not_its_stated_bus_waits() {
    let root = root();
    let scenario_path = scenario::find_scenario(&root, "thesis-demo");
    for revision in [None, Some("1-2")] {
        let files = scenario::timing_files_for(&root, revision);
        let chip = scenario::build_for(&root, &scenario_path, &files, Firmware::Production)
            .unwrap_or_else(|e| panic!("{revision:?}: {e}"));
        let qemu = scenario::build_for(&root, &scenario_path, &files, Firmware::Qemu)
            .unwrap_or_else(|e| panic!("{revision:?}: {e}"));
        for row in ["publisher[proximity-ring]", "power_monitor"] {
            let (on_chip, bound, waits) = job(&chip, "powermgmt", row);
            let (in_qemu, _, _) = job(&qemu, "powermgmt", row);
            assert!(waits > 1_000.0, "{row}: waits {waits}");
            assert!(
                (on_chip - bound).abs() < 1e-6,
                "{row}: {on_chip} vs {bound}"
            );
            // PowerManagement's `trace.qemu.budget_scale` is 2.
            let want = 2.0 * (bound - waits) + waits;
            assert!(
                (in_qemu - want).abs() < 1e-6,
                "{revision:?} {row}: {in_qemu} µs in QEMU, want {want} (bound {bound}, waits {waits})"
            );
        }
    }
}
