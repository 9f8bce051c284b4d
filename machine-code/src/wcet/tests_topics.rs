//! Known answers for a publisher's bound per topic ([`topics`]): a hand-assembled publisher whose
//! release loop samples topic A (a short sample) or topic B (through a wrapper, a sample with a poll
//! loop on a device flag), its job bounded with the loop at its stated 4 runs and each topic's job
//! with one release, the other topic's sample left out and B's own wait. Cycles from the Cortex-M3
//! TRM's table as in [`super::tests`] (ARM DDI 0337, table 18-1: data processing 1, LDR 2, PUSH
//! 1 + N, POP with the PC 1 + N + P, BL and B 1 + P, a conditional branch 1, taken 1 + P, P = 3; a
//! load from a peripheral whose base the code does not fix 5 more, APB1's; flash at 0 wait states);
//! a stated wait costs its loop's way out plus the wait, and one instruction per cycle of the wait.
use super::*;
use crate::testelf::{elf_with_lines, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// `PUB`: `push {r4, lr}`; the release loop at src/pub.rs:20 reads the next release (0: none), calls
/// `SAMPLE_A` for 1 and `WRAP_B` (which calls `SAMPLE_B`) otherwise, counts it and goes round;
/// `pop {r4, pc}`. `SAMPLE_B` polls a status word at src/pub.rs:40 until it is set.
fn publisher() -> Image {
    let code = thumb(&[
        0xb510, // 0x00 push {r4, lr}: 3
        0x6801, // 0x02 ldr r1, [r0]: 7 (the loop's header, line 20)
        0x2900, // 0x04 cmp r1, #0: 1
        0xd008, // 0x06 beq 0x1a: 1, taken 4
        0x2901, // 0x08 cmp r1, #1: 1
        0xd002, // 0x0a beq 0x12: 1, taken 4
        0xf000, 0xf80c, // 0x0c bl WRAP_B: 4
        0xe001, // 0x10 b 0x16: 4
        0xf000, 0xf803, // 0x12 bl SAMPLE_A: 4
        0x3401, // 0x16 adds r4, #1: 1
        0xe7f3, // 0x18 b 0x02: 4
        0xbd10, // 0x1a pop {r4, pc}: 6
        0x2001, // 0x1c SAMPLE_A: movs r0, #1: 1
        0x4770, // 0x1e bx lr: 4
        0x6802, // 0x20 SAMPLE_B: ldr r2, [r0]: 7 (the poll loop, line 40)
        0x2a00, // 0x22 cmp r2, #0: 1
        0xd0fc, // 0x24 beq 0x20: 1, taken 4
        0x4770, // 0x26 bx lr: 4
        0xb580, // 0x28 WRAP_B: push {r7, lr}: 3
        0xf7ff, 0xfff9, // 0x2a bl SAMPLE_B: 4
        0xbd80, // 0x2e pop {r7, pc}: 6
    ]);
    let bytes = elf_with_lines(
        &code,
        &[
            Sym::function("PUB", 0, 0x1c),
            Sym::function("SAMPLE_A", 0x1c, 4),
            Sym::function("SAMPLE_B", 0x20, 8),
            Sym::function("WRAP_B", 0x28, 8),
        ],
        "firmware/src/pub.rs",
        &[
            (0, 10),
            (2, 20),
            (0x1a, 22),
            (0x1c, 30),
            (0x20, 40),
            (0x26, 42),
            (0x28, 50),
        ],
    );
    Image::parse(&bytes).expect("the test image parses")
}

const LOOPS: &str = r#""loops":[{"function":"PUB","file":"src/pub.rs","line":20,"bound":4,"reason":"3 releases and the end"}],
    "waits":[{"function":"SAMPLE_B","file":"src/pub.rs","line":40,"wait_us":200,"source":"the driver's timeout"}]"#;

const TOPICS: &str = r#","topics":{"function":"PUB","file":"src/pub.rs","line":20,"reason":"one release per job",
    "groups":[{"name":"a","topics":["alpha"],"functions":["SAMPLE_A"],"reason":"only alpha's arm calls it"},
              {"name":"b","topics":["beta","gamma"],"functions":["SAMPLE_B"],"reason":"only beta's arm calls it",
               "waits":[{"function":"SAMPLE_B","file":"src/pub.rs","line":40,"wait_us":25,"source":"one byte"}]}]}"#;

fn bounds(topics: &str) -> BoundsFile {
    BoundsFile::parse(&format!("{{{LOOPS}{topics}}}")).expect("the bounds file parses")
}

fn pub_task() -> Task {
    Task {
        name: "pub".into(),
        entry: TaskEntry::Symbol("PUB".into()),
        handler: false,
    }
}

#[test]
fn each_topic_group_is_bounded_by_one_release_of_its_own_sample() {
    let img = publisher();
    let rows = bound_tasks(&img, &[pub_task()], F103_0WS, &bounds(TOPICS));
    let job = &rows[0];
    // SAMPLE_A: movs 1, bx 4 = 5 cycles, 2 instructions. SAMPLE_B: its poll loop's way out (ldr 7,
    // cmp 1, beq 1) and bx 4 = 13 cycles plus the wait; 4 instructions plus one a cycle of the wait
    // (200 µs: 14 400 at 72 MHz; 25 µs: 1 800). WRAP_B: push 3, bl 4, pop 6 = 13 cycles, 3
    // instructions, plus SAMPLE_B.
    // An iteration through B: ldr 7, cmp 1, beq 1, cmp 1, beq 1, bl 4, WRAP_B 26, b 4, adds 1, b 4 =
    // 50 cycles and the wait; 6 + 7 + 3 = 16 instructions and the wait's.
    // Through A: ldr 7, cmp 1, beq 1, cmp 1, beq taken 4, bl 4, SAMPLE_A 5, adds 1, b 4 = 28 cycles,
    // 10 instructions. The way out: ldr 7, cmp 1, beq taken 4 = 12, 3 instructions; push 3, pop 6.
    // The job, the header run 4 times: 3 + 3 × 50 + 12 + 6 = 171 cycles and 3 × 200 µs;
    // 1 + 3 × 14 416 + 3 + 1 = 43 253 instructions.
    assert_eq!(
        (
            job.cycles,
            job.instructions,
            job.bus_wait_us,
            job.declined.as_deref()
        ),
        (171, 43_253, 600.0, None)
    );
    assert_eq!(job.topics.len(), 2);
    let (a, b) = (&job.topics[0], &job.topics[1]);
    // Topic group a: B's sample left out (and WRAP_B, whose every path calls it), one release:
    // 3 + 12 + 6 + 28 = 49 cycles; 1 + 3 + 1 + 10 = 15 instructions; no wait.
    assert_eq!(
        (
            a.group.as_str(),
            a.cycles,
            a.instructions,
            a.bus_wait_us,
            a.declined.as_deref()
        ),
        ("a", 49, 15, 0.0, None)
    );
    // Topic group b: A's sample left out, one release, B's wait at the group's 25 µs:
    // 3 + 12 + 6 + 50 = 71 cycles and 25 µs; 1 + 3 + 1 + 16 + 1 800 = 1 821 instructions.
    assert_eq!(
        (
            b.group.as_str(),
            b.cycles,
            b.instructions,
            b.bus_wait_us,
            b.declined.as_deref()
        ),
        ("b", 71, 1_821, 25.0, None)
    );
    assert_eq!(b.topics, ["beta", "gamma"]);
    // 71 cycles at 72 MHz are 0.987 µs (rounded up to the ns), and the wait.
    assert_eq!(b.us, 25.987);
    assert!(b
        .loops
        .iter()
        .any(|l| l.function == "SAMPLE_B" && l.source.contains("one byte")));
    // Sound per release: a job serving beta, alpha and beta runs around the loop once (21 cycles)
    // and one iteration each (50 + 28 + 50): within the three topics' bounds.
    assert!(21 + 50 + 28 + 50 <= b.cycles + a.cycles + b.cycles);
    // A job that serves none (its way out alone, 21 cycles) is within either.
    assert!(21 <= a.cycles.min(b.cycles));
    // Without the statement, no topic's bound; the job's is unchanged.
    let rows = bound_tasks(&img, &[pub_task()], F103_0WS, &bounds(""));
    assert!(rows[0].topics.is_empty());
    assert_eq!(rows[0].cycles, 171);
}

#[test]
fn a_function_whose_every_path_calls_a_left_out_function_is_no_path_of_the_job() {
    let img = publisher();
    let file = bounds("");
    let wrap = img.function_named("WRAP_B").unwrap().start;
    // WRAP_B's entry block ends in its call of SAMPLE_B: left out, nothing of it remains.
    let mut analysis = analysis::Analysis::excluding(&img, F103_0WS, &file, &["SAMPLE_B".into()]);
    let outcome = analysis.summary(wrap).unwrap();
    assert!(
        outcome.as_ref().is_err_and(
            |r| r.contains("every path of WRAP_B calls a function this job does not call")
        ),
        "{outcome:?}"
    );
    // Left out of PUB in turn: its job is the loop through A (header run 4 times: 3 + 3 × 28 +
    // 12 + 6 = 105 cycles), B's arm gone.
    let start = img.function_named("PUB").unwrap().start;
    let b = to_bound(analysis.summary(start).unwrap());
    assert_eq!(
        (b.cycles, b.bus_wait_ns, b.declined.as_deref()),
        (105, 0, None)
    );
    // Without exclusions every function stays.
    let mut plain = analysis::Analysis::new(&img, F103_0WS, &file);
    let b = to_bound(plain.summary(wrap).unwrap());
    assert_eq!((b.cycles, b.declined.as_deref()), (13 + 13, None));
}

#[test]
fn a_release_loop_off_the_task_path_gives_no_topic_bounds() {
    let img = publisher();
    let sample = Task {
        name: "sample".into(),
        entry: TaskEntry::Symbol("WRAP_B".into()),
        handler: false,
    };
    let rows = bound_tasks(&img, &[sample], F103_0WS, &bounds(TOPICS));
    assert!(rows[0].topics.is_empty());
}

#[test]
fn topic_groups_need_topics_functions_a_reason_and_one_group_a_topic_per_image() {
    let refused = |topics: &str| {
        matches!(
            BoundsFile::parse(&format!("{{{LOOPS},\"topics\":{topics}}}")),
            Err(crate::Error::Bounds(_))
        )
    };
    let group = |name: &str, topics: &str, functions: &str, reason: &str| {
        format!(
            r#"{{"name":"{name}","topics":[{topics}],"functions":[{functions}],"reason":"{reason}"}}"#
        )
    };
    let statement = |groups: &[String]| {
        format!(
            r#"{{"function":"PUB","file":"src/pub.rs","line":20,"reason":"r","groups":[{}]}}"#,
            groups.join(",")
        )
    };
    assert!(!refused(&statement(&[group("a", r#""x""#, r#""F""#, "r")])));
    assert!(refused(&statement(&[])));
    assert!(refused(&statement(&[group("a", "", r#""F""#, "r")])));
    assert!(refused(&statement(&[group("a", r#""x""#, "", "r")])));
    assert!(refused(&statement(&[group("a", r#""x""#, r#""F""#, " ")])));
    // A topic may be in two groups (of two revisions' images), as long as one image holds one.
    let two = format!(
        "{{{LOOPS},\"topics\":{}}}",
        statement(&[
            group("a", r#""alpha""#, r#""SAMPLE_A""#, "r"),
            group("b", r#""alpha""#, r#""SAMPLE_B""#, "r"),
            group("c", r#""alpha""#, r#""ELSEWHERE""#, "r"),
        ])
    );
    let rows = bound_tasks(
        &publisher(),
        &[pub_task()],
        F103_0WS,
        &BoundsFile::parse(&two).unwrap(),
    );
    // c's function is not in the image: no bound of it. a and b both are: neither tells alpha's job.
    assert_eq!(rows[0].topics.len(), 2);
    for g in &rows[0].topics {
        assert!(
            g.declined
                .as_deref()
                .is_some_and(|r| r.contains("in two topic groups")),
            "{g:?}"
        );
    }
    // The missing places name a group's function no image has.
    let file = bounds(TOPICS);
    let img = publisher();
    assert!(file.missing_places(&img).is_empty());
    let absent = BoundsFile::parse(&format!(
        "{{{LOOPS},\"topics\":{}}}",
        statement(&[group("a", r#""x""#, r#""NOWHERE""#, "r")])
    ))
    .unwrap();
    assert_eq!(
        absent.missing_places(&img),
        ["topic group a function NOWHERE"]
    );
}

#[test]
fn a_group_states_its_own_loop_bounds_and_waits_in_place_of_the_files() {
    let file = BoundsFile::parse(&format!(
        r#"{{{LOOPS},"topics":{{"function":"PUB","file":"src/pub.rs","line":20,"reason":"r",
            "groups":[{{"name":"b","topics":["beta"],"functions":["SAMPLE_B"],"reason":"r",
                        "loops":[{{"function":"F","file":"src/f.rs","line":3,"bound":2,"reason":"one frame"}}],
                        "waits":[{{"function":"SAMPLE_B","file":"src/pub.rs","line":40,"wait_us":25,"source":"one byte"}}]}}]}}}}"#
    ))
    .unwrap();
    let per_topic = file.topics.clone().unwrap();
    let b = file.for_topic_group(&per_topic, &per_topic.groups[0]);
    // The release loop one pass in total; the group's loop and wait in place of the file's.
    assert_eq!(
        b.total("PUB", "x/src/pub.rs", 20).map(|t| t.passes),
        Some(1)
    );
    assert_eq!(b.loop_bound("F", "x/src/f.rs", 3).map(|l| l.bound), Some(2));
    assert_eq!(
        b.wait("SAMPLE_B", "x/src/pub.rs", 40).map(|w| w.wait_us),
        Some(25.0)
    );
    assert_eq!(b.waits.len(), 1);
    // A group loop without a bound or a reason is refused.
    for bad in [r#""bound":0,"reason":"r""#, r#""bound":2,"reason":" ""#] {
        let text = format!(
            r#"{{{LOOPS},"topics":{{"function":"PUB","file":"src/pub.rs","line":20,"reason":"r",
                "groups":[{{"name":"b","topics":["beta"],"functions":["SAMPLE_B"],"reason":"r",
                            "loops":[{{"function":"F","file":"src/f.rs","line":3,{bad}}}]}}]}}}}"#
        );
        assert!(matches!(
            BoundsFile::parse(&text),
            Err(crate::Error::Bounds(_))
        ));
    }
}

/// `PUB`'s release loop with each arm's sample under a lock of its own, as a sampler takes one around
/// a topic family's sample function: the arm saves BASEPRI, raises it to 0xc0 (priority 4), calls
/// `SAMPLE_A` or `WRAP_B` (→ `SAMPLE_B`, its poll at src/pub.rs:40) and restores it at the join. Both
/// raises are the publisher's own code, not the sample functions'; A's is in the block of its call, B's
/// in a block of its own before it (a branch between them), as a compiler may place a lock's raise.
fn locked_publisher() -> Image {
    let code = thumb(&[
        0xb530, // 0x00 push {r4, r5, lr}
        0x6801, // 0x02 ldr r1, [r0] (the loop's header, line 20)
        0x2900, // 0x04 cmp r1, #0
        0xd012, // 0x06 beq 0x2e
        0xf3ef, 0x8511, // 0x08 mrs r5, BASEPRI
        0x22c0, // 0x0c movs r2, #0xc0
        0x2901, // 0x0e cmp r1, #1
        0xd005, // 0x10 beq 0x1e
        0xf382, 0x8812, // 0x12 msr BASEPRI_MAX, r2: 2 (B's raise)
        0xe7ff, // 0x16 b 0x18: 4
        0xf000, 0xf810, // 0x18 bl WRAP_B: 4
        0xe003, // 0x1c b 0x26: 4
        0xf382, 0x8812, // 0x1e msr BASEPRI_MAX, r2: 2 (A's raise)
        0xf000, 0xf805, // 0x22 bl SAMPLE_A: 4
        0xf385, 0x8811, // 0x26 msr BASEPRI, r5: 2 (the restore of either)
        0x3401, // 0x2a adds r4, #1
        0xe7e9, // 0x2c b 0x02
        0xbd30, // 0x2e pop {r4, r5, pc}
        0x2001, // 0x30 SAMPLE_A: movs r0, #1: 1
        0x4770, // 0x32 bx lr: 4
        0x6802, // 0x34 SAMPLE_B: ldr r2, [r0] (the poll loop, line 40)
        0x2a00, // 0x36 cmp r2, #0
        0xd0fc, // 0x38 beq 0x34
        0x4770, // 0x3a bx lr
        0xb580, // 0x3c WRAP_B: push {r7, lr}
        0xf7ff, 0xfff9, // 0x3e bl SAMPLE_B
        0xbd80, // 0x42 pop {r7, pc}
    ]);
    let bytes = elf_with_lines(
        &code,
        &[
            Sym::function("PUB", 0, 0x30),
            Sym::function("SAMPLE_A", 0x30, 4),
            Sym::function("SAMPLE_B", 0x34, 8),
            Sym::function("WRAP_B", 0x3c, 8),
        ],
        "firmware/src/pub.rs",
        &[
            (0, 10),
            (2, 20),
            (0x2e, 22),
            (0x30, 30),
            (0x34, 40),
            (0x3a, 42),
            (0x3c, 50),
        ],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn a_lock_around_another_groups_sample_is_no_section_of_a_release() {
    let img = locked_publisher();
    let file = bounds(TOPICS);
    let p4 = Ceiling::Basepri {
        hardware: 0xc0,
        priority: 4,
    };
    let at_p4 = |s: &TaskSections| {
        assert_eq!(s.incomplete, None);
        s.ceilings.iter().find(|c| c.ceiling == p4).map(|c| {
            (
                c.sections,
                c.bus_wait_us,
                c.function.clone(),
                c.declined.clone(),
            )
        })
    };
    // The whole task: both raises, the longest B's with the file's 200 µs wait.
    let whole = task_sections(&img, &[pub_task()], F103_0WS, &file).remove(0);
    assert_eq!(at_p4(&whole), Some((2, 200.0, "PUB".into(), None)));
    let groups = topic_sections(&img, &pub_task(), F103_0WS, &file);
    let names: Vec<&str> = groups.iter().map(|(g, _)| g.as_str()).collect();
    assert_eq!(names, ["a", "b"]);
    // Group a: B's call of WRAP_B is left out, and B's raise before it with it (its block has no way
    // on but to that call): A's section alone, no wait.
    assert_eq!(at_p4(&groups[0].1), Some((1, 0.0, "PUB".into(), None)));
    // Group b: A's call left out with its raise (in the call's block), B's section with the group's
    // own 25 µs wait.
    assert_eq!(at_p4(&groups[1].1), Some((1, 25.0, "PUB".into(), None)));
    // A's section: msr 2, bl 4, SAMPLE_A 5, msr 2 = 13 cycles; B's: msr 2, b 4, bl 4, WRAP_B 26 (its
    // poll loop's way out), b 4, msr 2 = 42 cycles and the wait.
    let cycles = |s: &TaskSections| s.ceilings.iter().map(|c| c.cycles).collect::<Vec<_>>();
    assert_eq!(
        (cycles(&whole), cycles(&groups[0].1), cycles(&groups[1].1)),
        (vec![42], vec![13], vec![42])
    );
    // Without topics in the file, no group's sections.
    assert!(topic_sections(&img, &pub_task(), F103_0WS, &bounds("")).is_empty());
}
