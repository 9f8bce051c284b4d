//! The generated bounds file's reader (`schedule_analysis::bounds`): a valid file reads and gives budgets, and
//! every malformed one is refused with its field named.

use schedule_analysis::bounds::*;
const HASH: &str = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";

fn sample() -> serde_json::Value {
    serde_json::json!({
        "generated": format!("{GENERATED_PREFIX} from target/thumbv7m-none-eabi/release/diwheeldrive; do not edit"),
        "board": "diwheeldrive",
        "revision": "1-1",
        "chip": "stm32f103",
        "clock_hz": 72_000_000,
        "wait_states": 2,
        "image": { "code_sha256": HASH, "code_bytes": 40_000 },
        "tasks": [
            { "task": "can_rx", "cycles": 180, "us": 2.5, "instructions": 120, "bus_wait_us": 0.0,
              "declined": null,
              "critical_sections": { "critical_section": { "cycles": 36, "us": 0.5, "declined": null } } },
            { "task": "publisher[gyroscope]", "cycles": 720, "us": 10.0, "instructions": 400,
              "bus_wait_us": 22.5, "declined": null },
            { "task": "admit_requests", "cycles": null, "us": null, "instructions": null,
              "declined": "loop in schedule_analysis::admission::analyse_board (admission.rs:812) has no bound" }
        ]
    })
}

fn read(v: &serde_json::Value) -> Result<BoundsFile, BoundsError> {
    BoundsFile::from_json("x.wcet.json", &v.to_string())
}

#[test]
fn a_valid_file_reads_and_gives_budgets() {
    let b = read(&sample()).unwrap();
    assert_eq!(b.chip.short(), "F103");
    assert_eq!(b.task("can_rx").unwrap().budget_us(), Some(2.5));
    assert_eq!(
        b.task("publisher[gyroscope]").unwrap().budget_us(),
        Some(32.5)
    );
    assert_eq!(b.task("admit_requests").unwrap().budget_us(), None);
    assert_eq!(
        b.task("can_rx").unwrap().critical_sections["critical_section"].length_us(),
        Some(0.5)
    );
    // What the writer writes, the reader reads.
    assert_eq!(BoundsFile::from_json("x", &b.to_json()).unwrap(), b);
}

fn error_of(edit: impl FnOnce(&mut serde_json::Value)) -> BoundsError {
    let mut v = sample();
    edit(&mut v);
    read(&v).unwrap_err()
}

#[test]
fn every_error_names_its_field() {
    type Edit = Box<dyn FnOnce(&mut serde_json::Value)>;
    let cases: Vec<(Edit, &str, Problem)> = vec![
        (
            Box::new(|v| v["generated"] = "hand-written".into()),
            "generated",
            Problem::NotGenerated,
        ),
        (
            Box::new(|v| v["clock_hz"] = 0.into()),
            "clock_hz",
            Problem::NotPositive,
        ),
        (
            Box::new(|v| v["image"]["code_sha256"] = "ABC".into()),
            "image.code_sha256",
            Problem::NotAHash,
        ),
        (
            Box::new(|v| v["tasks"][1]["task"] = "can_rx".into()),
            "tasks[1].task",
            Problem::Duplicate,
        ),
        (
            Box::new(|v| v["tasks"][0]["us"] = 3.0.into()),
            "tasks[0].us",
            Problem::UsDisagrees {
                expected: 2.5,
                got: 3.0,
            },
        ),
        (
            Box::new(|v| v["tasks"][0]["declined"] = "no reason to".into()),
            "tasks[0].declined",
            Problem::BoundAndDeclined,
        ),
        (
            Box::new(|v| v["tasks"][2]["declined"] = serde_json::Value::Null),
            "tasks[2].cycles",
            Problem::NeitherBoundNorDeclined,
        ),
        (
            Box::new(|v| v["tasks"][2]["declined"] = " ".into()),
            "tasks[2].declined",
            Problem::Empty,
        ),
        (
            Box::new(|v| v["tasks"][1]["bus_wait_us"] = (-1.0).into()),
            "tasks[1].bus_wait_us",
            Problem::NotFinite(-1.0),
        ),
        (
            Box::new(|v| v["tasks"][0]["critical_sections"]["critical_section"]["us"] = 9.0.into()),
            "tasks[0].critical_sections.critical_section.us",
            Problem::UsDisagrees {
                expected: 0.5,
                got: 9.0,
            },
        ),
    ];
    for (edit, field, problem) in cases {
        let e = error_of(edit);
        assert_eq!(e.field, field, "{e}");
        assert_eq!(e.problem, problem, "{e}");
        assert!(e.to_string().contains(field));
    }
}

#[test]
fn serde_errors_name_the_field_too() {
    let e = error_of(|v| v["chip"] = "stm32f999".into());
    assert_eq!(e.field, "chip");
    let e = error_of(|v| v["tasks"][0]["cylces"] = 1.into());
    assert_eq!(e.field, "tasks[0].cylces");
    assert!(e.to_string().contains("cylces"), "{e}");
    let e = error_of(|v| {
        v.as_object_mut().unwrap().remove("image");
    });
    assert!(e.to_string().contains("image"), "{e}");
}

#[test]
fn a_file_for_another_image_is_refused() {
    let b = read(&sample()).unwrap();
    assert!(b.check_image("f", "diwheeldrive", Some("1-1")).is_ok());
    let e = b.check_image("f", "diwheeldrive", Some("1-2")).unwrap_err();
    assert_eq!(e.field, "revision");
    assert!(e.to_string().contains("diwheeldrive 1-1"), "{e}");
    assert_eq!(
        b.check_image("f", "lightring", Some("1-1"))
            .unwrap_err()
            .field,
        "board"
    );
}

#[test]
fn names_follow_the_image() {
    assert_eq!(
        file_name("diwheeldrive", Some("1-1")),
        "diwheeldrive-1-1.wcet.json"
    );
    assert_eq!(file_name("powermgmt", None), "powermgmt.wcet.json");
    assert_eq!(
        revision_of_features(&["qemu".into(), "rev-1-0".into()]),
        Some("1-0")
    );
    assert_eq!(revision_of_features(&[]), None);
    let dir = std::env::temp_dir().join(format!("bounds-none-{}", std::process::id()));
    assert_eq!(
        BoundsFile::read(&dir.join("nothing.wcet.json"), "n").unwrap(),
        None
    );
}
