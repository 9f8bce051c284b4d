//! Known answers for one software task's part of its dispatcher ([`super::polled`]): a hand-assembled
//! dispatcher polling two tasks, DWARF naming which instructions each task's inlined poll is, each
//! task's bound worked out from the Cortex-M3 TRM's cycle table as in [`super::tests`] (data
//! processing 1, PUSH/POP 1 + N, `CBZ` 1 and + P when taken, a taken branch 1 + P, P = 3; flash at 0
//! wait states: a line of 8 bytes costs 1, hidden by the instructions here).
use super::polled::is_task_body;
use super::*;
use crate::testelf::{elf_with_inlines, Inlines, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// The dispatcher `DISPATCH`: `fast` polled when r0 is set (five moves), then `slow` when r1 is (a
/// counted loop of 8 passes and three more instructions, interrupts off for them); each poll inlined,
/// as DWARF says (or, without `with_inlines`, says nothing of them).
fn dispatcher(with_inlines: bool) -> Image {
    let inlined = [
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        ("board::app::slow::{{closure}}", 0x10, 0x1e),
    ];
    build(&CODE, if with_inlines { &inlined } else { &[] })
}

/// The dispatcher's code.
const CODE: [u16; 16] = [
    0xb510, // 0x00 push {r4, lr}: 1 + 2
    0xb120, // 0x02 cbz r0, 0x0e: 1, taken + P (fast not pending)
    0x2201, // 0x04 movs r2, #1: fast's poll, 1 each
    0x2202, // 0x06 movs r2, #2
    0x2203, // 0x08 movs r2, #3
    0x2204, // 0x0a movs r2, #4
    0x2205, // 0x0c movs r2, #5
    0xb131, // 0x0e cbz r1, 0x1e: 1, taken + P (slow not pending)
    0x2300, // 0x10 movs r3, #0: slow's poll: 1
    0x3301, // 0x12 adds r3, #1: 1 (8 passes)
    0x2b08, // 0x14 cmp r3, #8: 1
    0xd1fc, // 0x16 bne 0x12: 1, taken + P
    0xb672, // 0x18 cpsid i: 1 (interrupts off, slow's section)
    0xbf00, // 0x1a nop: 1
    0xb662, // 0x1c cpsie i: 1
    0xbd10, // 0x1e pop {r4, pc}: 1 + 2 + P
];

/// An image of `DISPATCH` (`code`, 32 bytes) with `inlined` as its DWARF inlined subroutines.
fn build(code: &[u16], inlined: &[(&str, u64, u64)]) -> Image {
    let functions = [Inlines {
        function: ("DISPATCH", 0, 0x20),
        inlined,
    }];
    let bytes = elf_with_inlines(
        &thumb(code),
        &[Sym::function("DISPATCH", 0, 0x20)],
        "board/src/main.rs",
        &[(0, 10)],
        &functions,
    );
    Image::parse(&bytes).expect("the test image parses")
}

fn part(task: &str, other: &str) -> Task {
    Task {
        name: task.into(),
        entry: TaskEntry::Polled {
            dispatcher: "DISPATCH".into(),
            task: task.into(),
            others: vec![other.into()],
        },
        handler: false,
    }
}

fn rows(image: &Image) -> Vec<(String, u64, u64)> {
    let whole = Task {
        name: "dispatcher".into(),
        entry: TaskEntry::Symbol("DISPATCH".into()),
        handler: false,
    };
    let tasks = [whole, part("fast", "slow"), part("slow", "fast")];
    bound_tasks(image, &tasks, F103_0WS, &BoundsFile::default())
        .into_iter()
        .map(|t| {
            assert_eq!(t.declined, None);
            (t.task, t.cycles, t.instructions)
        })
        .collect()
}

#[test]
fn dwarf_names_the_inlined_polls() {
    let img = dispatcher(true);
    assert_eq!(
        img.inlined_at(0x06),
        ["board::app::fast::{{closure}}", "DISPATCH"]
    );
    assert_eq!(img.inlined_at(0x02), ["DISPATCH"]);
    assert!(is_task_body("board::app::fast::{{closure}}", "fast"));
    assert!(!is_task_body("board::app::breakfast::{{closure}}", "fast"));
    assert!(!is_task_body(
        "board::app::fast::{{closure}}::{{closure}}",
        "fast"
    ));
}

#[test]
fn each_task_is_bounded_by_the_dispatcher_and_its_own_poll() {
    let found = rows(&dispatcher(true));
    // The whole dispatcher, both pending: push 3 + cbz 1, fast 5, cbz 1, slow: movs 1 + 8 passes
    // of 3 and 7 branches back of P + 3 more, pop 6: 4 + 5 + 1 + 1 + 45 + 3 + 6 = 65 cycles;
    // 2 + 5 + 1 + 1 + 24 + 3 + 1 = 37 instructions.
    assert_eq!(found[0], ("dispatcher".into(), 65, 37));
    // fast's job: its poll, then slow's check taken past slow's poll (1 + P):
    // 4 + 5 + 4 + 6 = 19 cycles; 2 + 5 + 1 + 1 = 9 instructions.
    assert_eq!(found[1], ("fast".into(), 19, 9));
    // slow's job: fast's check taken past fast's poll (push 3 + 1 + P), then slow's poll:
    // 7 + 1 + 1 + 45 + 3 + 6 = 63 cycles; 2 + 1 + 1 + 24 + 3 + 1 = 32 instructions.
    assert_eq!(found[2], ("slow".into(), 63, 32));
}

#[test]
fn without_the_polls_in_dwarf_a_task_is_bounded_by_the_whole_dispatcher() {
    let found = rows(&dispatcher(false));
    assert!(
        found.iter().all(|(_, c, i)| (*c, *i) == (65, 37)),
        "{found:?}"
    );
}

#[test]
fn each_task_has_the_sections_of_its_own_part() {
    let img = dispatcher(true);
    let tasks = [part("fast", "slow"), part("slow", "fast")];
    let found = task_sections(&img, &tasks, F103_0WS, &BoundsFile::default());
    // fast's part holds no raise; slow's the interrupts-off section `cpsid i; nop; cpsie i`:
    // 3 cycles, 3 instructions.
    assert_eq!(found[0].task, "fast");
    assert!(found[0].ceilings.is_empty(), "{:?}", found[0]);
    assert_eq!(found[0].incomplete, None);
    let slow: Vec<(Ceiling, u64, u64)> = found[1]
        .ceilings
        .iter()
        .map(|c| (c.ceiling, c.cycles, c.instructions))
        .collect();
    assert_eq!(slow, [(Ceiling::InterruptsOff, 3, 3)]);
}

#[test]
fn a_task_whose_code_only_another_task_reaches_is_bounded_by_the_whole_dispatcher() {
    // fast's poll split by a branch over one move (`b 0x08`, 1 + P, in place of `movs r2, #1`),
    // DWARF naming its first block slow's: the block of fast's own behind it is reached only
    // through a block named another task's, so the attribution does not tell the polls apart and
    // fast is bounded by the whole dispatcher: 65 − 2 moves + 4 = 67 cycles, 37 − 1 = 36
    // instructions.
    let mut code = CODE;
    code[2] = 0xe000; // 0x04 b 0x08 (0x06 skipped)
    let split = [
        ("board::app::slow::{{closure}}", 0x04, 0x08),
        ("board::app::fast::{{closure}}", 0x08, 0x0e),
        ("board::app::slow::{{closure}}", 0x10, 0x1e),
    ];
    let img = build(&code, &split);
    let found = rows(&img);
    assert_eq!(found[0], ("dispatcher".into(), 67, 36));
    assert_eq!(found[1], ("fast".into(), 67, 36));
    // Named as the code runs, fast's part is its own again: 19 − 2 + 4 = 21 cycles, 8 instructions.
    let named = [
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        ("board::app::slow::{{closure}}", 0x10, 0x1e),
    ];
    assert_eq!(rows(&build(&code, &named))[1], ("fast".into(), 21, 8));
}

#[test]
fn a_task_whose_way_returns_only_through_another_tasks_poll_is_bounded_by_the_whole_dispatcher() {
    // fast's poll either ends at once (`cbz r2`) or runs three moves and branches into slow's poll
    // (code LLVM shares between the two), past slow's first instruction, and returns through the
    // rest of it. With slow's blocks left out that way ends nowhere, and fast's part would be its
    // short way alone: push 3 + cbz 1, cbz 1 + P, cbz 1 + P, pop 6 = 18 cycles, 5 instructions,
    // where a run of fast's job takes 22 cycles. So fast is bounded by the whole dispatcher, whose
    // longest path is that run: push 3 + cbz 1, cbz 1, three moves 3 + b 4, slow's rest 1 + 3,
    // pop 6 = 22 cycles; 2 + 1 + 4 + 1 + 3 + 1 = 12 instructions.
    let code = [
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0xb120, // 0x02 cbz r0, 0x0e: 1, taken + P (fast not pending)
        0xb11a, // 0x04 cbz r2, 0x0e: 1, taken + P (fast's poll: done at once)
        0x2201, // 0x06 movs r2, #1: 1 each
        0x2202, // 0x08 movs r2, #2
        0x2203, // 0x0a movs r2, #3
        0xe001, // 0x0c b 0x12: 1 + P (into slow's poll)
        0xb121, // 0x0e cbz r1, 0x1a: 1, taken + P (slow not pending)
        0xe000, // 0x10 b 0x14: 1 + P (slow's poll)
        0x2301, // 0x12 movs r3, #1: 1 each
        0x2302, // 0x14 movs r3, #2
        0x2303, // 0x16 movs r3, #3
        0x2304, // 0x18 movs r3, #4
        0xbd10, // 0x1a pop {r4, pc}: 1 + 2 + P
        0xbf00, // 0x1c
        0xbf00, // 0x1e
    ];
    let inlined = [
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        ("board::app::slow::{{closure}}", 0x10, 0x1a),
    ];
    let found = rows(&build(&code, &inlined));
    assert_eq!(found[0], ("dispatcher".into(), 22, 12));
    assert_eq!(found[1], ("fast".into(), 22, 12));
}

#[test]
fn executor_code_that_goes_on_only_into_another_tasks_poll_stays_in_that_tasks_part() {
    // fast's pending check falls through into the executor's code ahead of fast's poll (a move and
    // a branch into the poll, named no task's), which goes on only through fast's poll; then slow's
    // check and poll. With fast's poll left out of slow's part that code ends nowhere, but slow's
    // own code does not lead to it: a job of slow that runs it runs fast's poll first, a job of
    // fast's, and slow's part takes fast's check past both.
    let code = [
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0xb120, // 0x02 cbz r0, 0x0e: 1, taken + P (fast not pending)
        0x2200, // 0x04 movs r2, #0: 1 (the executor's code ahead of fast's poll)
        0xe7ff, // 0x06 b 0x08: 1 + P (into fast's poll)
        0x2201, // 0x08 movs r2, #1: fast's poll, 1 each
        0x2202, // 0x0a movs r2, #2
        0x2203, // 0x0c movs r2, #3
        0xb119, // 0x0e cbz r1, 0x18: 1, taken + P (slow not pending)
        0x2301, // 0x10 movs r3, #1: slow's poll, 1 each
        0x2302, // 0x12 movs r3, #2
        0x2303, // 0x14 movs r3, #3
        0x2304, // 0x16 movs r3, #4
        0xbd10, // 0x18 pop {r4, pc}: 1 + 2 + P
        0xbf00, // 0x1a
        0xbf00, // 0x1c
        0xbf00, // 0x1e
    ];
    let inlined = [
        ("board::app::fast::{{closure}}", 0x08, 0x0e),
        ("board::app::slow::{{closure}}", 0x10, 0x18),
    ];
    let found = rows(&build(&code, &inlined));
    // The whole dispatcher, both pending: push 3 + cbz 1, move 1 + b 4, fast 3, cbz 1, slow 4,
    // pop 6 = 23 cycles; 1 + 1 + 1 + 1 + 3 + 1 + 4 + 1 = 13 instructions.
    assert_eq!(found[0], ("dispatcher".into(), 23, 13));
    // fast's job: its way in and poll, slow's check taken (1 + P): 3 + 1 + 5 + 3 + 4 + 6 = 22
    // cycles; 1 + 1 + 2 + 3 + 1 + 1 = 9 instructions.
    assert_eq!(found[1], ("fast".into(), 22, 9));
    // slow's job: fast's check taken (1 + P) past the executor's code and fast's poll, then slow's
    // poll: 3 + 4 + 1 + 4 + 6 = 18 cycles; 1 + 1 + 1 + 4 + 1 = 8 instructions. A run polling both
    // (23 cycles) is two jobs, charged 22 + 18.
    assert_eq!(found[2], ("slow".into(), 18, 8));
}

/// `AsyncTaskExecutor<F>::poll`'s instance for one task, mangled as rustc names it: the hash tells
/// the instances apart.
const EXECUTOR_FAST: &str =
    "_ZN4rtic6export8executor26AsyncTaskExecutor$LT$F$GT$4poll17h0000000000000001E";
const EXECUTOR_SLOW: &str =
    "_ZN4rtic6export8executor26AsyncTaskExecutor$LT$F$GT$4poll17h0000000000000002E";

#[test]
fn another_tasks_executor_code_after_this_tasks_poll_stays_in_that_tasks_part() {
    // fast is polled first; its poll ends in slow's pending check, whose pending way runs the
    // executor's code ahead of slow's poll (a move and a branch, named no task's body) and then
    // slow's poll. That code goes on only through slow's poll, and fast's code leads to it (through
    // slow's check): the rule for code named no task's cannot tell it from code LLVM shares between
    // two polls, so without the executor's instances fast is bounded by the whole dispatcher. DWARF
    // names the check and that code as inlined from slow's instance of the executor's poll (the
    // instance that inlines slow's body, not fast's): slow's way, in slow's part.
    let code = [
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0xb120, // 0x02 cbz r0, 0x0e: 1, taken + P (fast not pending)
        0x2201, // 0x04 movs r2, #1: fast's poll, 1 each
        0x2202, // 0x06 movs r2, #2
        0x2203, // 0x08 movs r2, #3
        0x2204, // 0x0a movs r2, #4
        0x2205, // 0x0c movs r2, #5
        0xb121, // 0x0e cbz r1, 0x1a: 1, taken + P (slow not pending): slow's executor
        0x2300, // 0x10 movs r3, #0: 1 (slow's executor, ahead of its poll)
        0xe7ff, // 0x12 b 0x14: 1 + P (into slow's poll)
        0x2301, // 0x14 movs r3, #1: slow's poll, 1 each
        0x2302, // 0x16 movs r3, #2
        0x2303, // 0x18 movs r3, #3
        0xbd10, // 0x1a pop {r4, pc}: 1 + 2 + P
        0xbf00, // 0x1c
        0xbf00, // 0x1e
    ];
    let bodies = [
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        ("board::app::slow::{{closure}}", 0x14, 0x1a),
    ];
    let found = rows(&build(&code, &bodies));
    // The whole dispatcher, both pending: push 3 + cbz 1, fast 5, cbz 1, move 1 + b 4, slow 3,
    // pop 6 = 24 cycles; 2 + 5 + 1 + 2 + 3 + 1 = 14 instructions.
    assert_eq!(found[0], ("dispatcher".into(), 24, 14));
    assert_eq!(found[1], ("fast".into(), 24, 14));
    let with_executors = [
        (EXECUTOR_FAST, 0x02, 0x0e),
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        (EXECUTOR_SLOW, 0x0e, 0x1a),
        ("board::app::slow::{{closure}}", 0x14, 0x1a),
    ];
    let img = build(&code, &with_executors);
    assert_eq!(
        img.inlined_at(0x06),
        [
            "board::app::fast::{{closure}}",
            "rtic::export::executor::AsyncTaskExecutor<F>::poll",
            "DISPATCH"
        ]
    );
    let found = rows(&img);
    assert_eq!(found[0], ("dispatcher".into(), 24, 14));
    // fast's job: its poll, then slow's check taken past slow's executor code and poll (1 + P):
    // 3 + 1 + 5 + 4 + 6 = 19 cycles; 2 + 5 + 1 + 1 = 9 instructions.
    assert_eq!(found[1], ("fast".into(), 19, 9));
    // slow's job: fast's check taken (1 + P), slow's check 1, its executor's move 1 and branch
    // 1 + P, its poll 3, pop 6: 3 + 4 + 1 + 1 + 4 + 3 + 6 = 22 cycles; 2 + 1 + 2 + 3 + 1 = 9
    // instructions.
    assert_eq!(found[2], ("slow".into(), 22, 9));
}

#[test]
fn code_of_another_tasks_executor_that_this_tasks_poll_flows_into_stays_checked() {
    // As above, but fast's poll branches straight into slow's executor code ahead of slow's poll
    // (`b 0x10` in place of fast's last move: code LLVM could have merged), which goes on only
    // through slow's poll: fast's own code flows into it directly, so it is fast's way, and fast
    // is bounded by the whole dispatcher: its longest path is that run, push 3 + cbz 1, four moves
    // 4 + b 4, slow's executor move 1 + b 4, slow's poll 3, pop 6 = 26 cycles; 2 + 5 + 2 + 3 + 1 =
    // 13 instructions.
    let code = [
        0xb510, // 0x00 push {r4, lr}
        0xb120, // 0x02 cbz r0, 0x0e
        0x2201, // 0x04 movs r2, #1: fast's poll
        0x2202, // 0x06 movs r2, #2
        0x2203, // 0x08 movs r2, #3
        0x2204, // 0x0a movs r2, #4
        0xe000, // 0x0c b 0x10: 1 + P (into slow's executor code)
        0xb121, // 0x0e cbz r1, 0x1a
        0x2300, // 0x10 movs r3, #0: slow's executor
        0xe7ff, // 0x12 b 0x14
        0x2301, // 0x14 movs r3, #1: slow's poll
        0x2302, // 0x16 movs r3, #2
        0x2303, // 0x18 movs r3, #3
        0xbd10, // 0x1a pop {r4, pc}
        0xbf00, // 0x1c
        0xbf00, // 0x1e
    ];
    let with_executors = [
        (EXECUTOR_FAST, 0x02, 0x0e),
        ("board::app::fast::{{closure}}", 0x04, 0x0e),
        (EXECUTOR_SLOW, 0x0e, 0x1a),
        ("board::app::slow::{{closure}}", 0x14, 0x1a),
    ];
    let found = rows(&build(&code, &with_executors));
    assert_eq!(found[0], ("dispatcher".into(), 26, 13));
    assert_eq!(found[1], ("fast".into(), 26, 13));
}
