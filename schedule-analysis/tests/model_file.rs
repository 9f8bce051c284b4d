//! The model file: the issue's JSON is accepted as written and analysed with both frame-cost models; defaults,
//! explicit blocking and every kind of malformed input (each error names its field).

use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::{FrameCostSpec, Model};
use schedule_analysis::report::{self, Format, Report};
use schedule_analysis::time::Time;

/// Exactly the JSON of issue 4.
const ISSUE_MODEL: &str = r#"
  {
    "boards": [
      { "name": "diwheeldrive",
        "tasks": [
          { "name": "gyroscope", "priority": 3, "wcet_us": 12.5, "period_us": 1000,
            "deadline_us": 1000, "jitter_us": 0,
            "critical_sections_us": { "tx_queue": 2.0 } } ] } ],
    "can": {
      "bitrate": 1000000,
      "frame_cost": "exact",
      "messages": [
        { "name": "gyroscope", "id": 1544, "dlc": 6, "period_us": 1000,
          "deadline_us": 1000, "jitter_us": 0, "sender": "diwheeldrive/gyroscope" } ] }
  }
"#;

fn error_of(json: &str) -> String {
    match Model::from_json(json).and_then(|m| m.validate().map(|_| ())) {
        Ok(()) => panic!("accepted: {json}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_issue_model_is_accepted_and_analysed_with_both_frame_costs() {
    let model = Model::from_json(ISSUE_MODEL).expect("the issue's JSON parses");
    let system = model.validate().expect("and validates");

    let exact = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    let task = &exact.boards[0].tasks[0];
    assert_eq!(task.wcrt(), Some(Time::from_ns(12_500)));
    assert_eq!(task.blocking, Time::ZERO);
    // 6 data bytes: 55 + 60 = 115 bits = 115 µs; the sender's response variation (12.5 − 0) is queuing jitter.
    let message = &exact.bus.as_ref().expect("bus").messages[0];
    assert_eq!(message.frame_time, Time::from_us(115));
    assert_eq!(message.jitter, Time::from_ns(12_500));
    assert_eq!(message.wcrt(), Some(Time::from_ns(127_500)));
    assert!(exact.all_ok());

    let thesis = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Thesis,
            horizon: None,
        },
    );
    let message = &thesis.bus.as_ref().expect("bus").messages[0];
    assert_eq!(message.frame_time, Time::from_us(545));
    assert_eq!(message.wcrt(), Some(Time::from_ns(557_500)));

    let fixed = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Micros(200.0),
            horizon: None,
        },
    );
    assert_eq!(
        fixed.bus.as_ref().expect("bus").messages[0].wcrt(),
        Some(Time::from_ns(212_500))
    );
}

#[test]
fn json_report_has_the_promised_fields() {
    let system = Model::from_json(ISSUE_MODEL)
        .and_then(|m| m.validate())
        .expect("valid");
    let report = Report::build(&system, "issue".into(), Vec::new(), Vec::new(), None);
    let json: serde_json::Value =
        serde_json::from_str(&report::render(&report, Format::Json)).expect("JSON");
    let task = &json["tasks"][0];
    for field in ["board", "name", "wcrt_us", "blocking_us", "schedulable"] {
        assert!(task.get(field).is_some(), "tasks[0].{field} missing");
    }
    assert_eq!(task["board"], "diwheeldrive");
    assert_eq!(task["wcrt_us"], 12.5);
    let message = &json["messages"][0];
    for field in ["name", "wcrt_us", "schedulable"] {
        assert!(message.get(field).is_some(), "messages[0].{field} missing");
    }
    assert_eq!(message["wcrt_us"], 127.5);
    // Both frame-cost models, since none was chosen.
    assert_eq!(json["frame_cost"], "exact");
    assert_eq!(json["comparison"]["frame_cost"], "thesis");
    assert_eq!(json["comparison"]["messages"][0]["wcrt_us"], 557.5);
    assert_eq!(json["schedulable"], true);
}

#[test]
fn optional_fields_take_their_defaults() {
    let model = Model::from_json(
        r#"{ "boards": [ { "name": "b", "tasks": [ { "name": "t", "priority": 1, "wcet_us": 1, "period_us": 250.5 } ] } ],
             "can": { "messages": [ { "name": "m", "id": 5, "dlc": 0, "period_us": 400 } ] } }"#,
    )
    .expect("parses");
    let system = model.validate().expect("valid");
    let task = &system.boards[0].tasks[0];
    assert_eq!(task.deadline, Time::from_ns(250_500));
    assert_eq!(task.jitter, Time::ZERO);
    let bus = system.bus.as_ref().expect("bus");
    assert_eq!(bus.bitrate, 1_000_000);
    assert_eq!(bus.frame_cost, FrameCostSpec::Exact);
    assert_eq!(bus.messages[0].deadline, Time::from_us(400));
    assert_eq!(bus.messages[0].frames, 1);
}

#[test]
fn explicit_blocking_replaces_the_computed_one() {
    let json = |blocking: &str| {
        format!(
            r#"{{ "boards": [ {{ "name": "b", "tasks": [
                {{ "name": "high", "priority": 2, "wcet_us": 1, "period_us": 100, "critical_sections_us": {{ "r": 1 }} {blocking} }},
                {{ "name": "low", "priority": 1, "wcet_us": 10, "period_us": 100, "critical_sections_us": {{ "r": 7 }} }} ] }} ] }}"#
        )
    };
    let options = Options {
        frame_cost: FrameCostSpec::Exact,
        horizon: None,
    };
    let computed = analyse(
        &Model::from_json(&json(""))
            .and_then(|m| m.validate())
            .expect("valid"),
        &options,
    );
    assert_eq!(computed.boards[0].tasks[0].blocking, Time::from_us(7));
    assert_eq!(computed.boards[0].tasks[0].wcrt(), Some(Time::from_us(8)));
    let imported = analyse(
        &Model::from_json(&json(r#", "blocking_us": 3"#))
            .and_then(|m| m.validate())
            .expect("valid"),
        &options,
    );
    assert_eq!(imported.boards[0].tasks[0].blocking, Time::from_us(3));
    assert_eq!(imported.boards[0].tasks[0].wcrt(), Some(Time::from_us(4)));
}

#[test]
fn an_overloaded_set_is_a_verdict_not_a_hang() {
    let system = Model::from_json(
        r#"{ "boards": [ { "name": "b", "tasks": [
            { "name": "a", "priority": 2, "wcet_us": 60, "period_us": 100 },
            { "name": "z", "priority": 1, "wcet_us": 50, "period_us": 100 } ] } ] }"#,
    )
    .and_then(|m| m.validate())
    .expect("valid");
    let a = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    assert!(a.boards[0].tasks[0].schedulable());
    assert!(
        a.boards[0].tasks[1].wcrt().is_none(),
        "utilisation 1.1: no bound"
    );
    assert!(!a.all_ok());
    assert_eq!(a.failures(), vec!["b/z".to_string()]);
}

#[test]
fn the_model_round_trips_through_json() {
    let model = Model::from_json(ISSUE_MODEL).expect("parses");
    assert_eq!(Model::from_json(&model.to_json()), Ok(model));
}

#[test]
fn malformed_models_name_the_field() {
    let task = |fields: &str| {
        format!(r#"{{ "boards": [ {{ "name": "b", "tasks": [ {{ {fields} }} ] }} ] }}"#)
    };
    let cases: Vec<(String, &str, &str)> = vec![
        (task(r#""name": "t", "priority": 1, "period_us": 10"#), "boards[0].tasks[0]", "wcet_us"),
        (task(r#""name": "t", "priority": 1, "wcet_us": "fast", "period_us": 10"#), "boards[0].tasks[0].wcet_us", "invalid type"),
        (task(r#""name": "t", "priority": 1, "wcet_us": 1, "period_us": 10, "deadline": 5"#), "boards[0].tasks[0]", "unknown field `deadline`"),
        (task(r#""name": "t", "priority": -1, "wcet_us": 1, "period_us": 10"#), "boards[0].tasks[0].priority", "invalid value"),
        (task(r#""name": "t", "priority": 1, "wcet_us": 1, "period_us": 0"#), "boards[0].tasks[0].period_us", "> 0"),
        (task(r#""name": "t", "priority": 1, "wcet_us": -2, "period_us": 10"#), "boards[0].tasks[0].wcet_us", "≥ 0"),
        (task(r#""name": "t", "priority": 1, "wcet_us": 1, "period_us": 10, "critical_sections_us": { "r": 4 }"#), "boards[0].tasks[0].critical_sections_us.r", "longer than"),
        (task(r#""name": "t", "priority": 1, "wcet_us": 1, "period_us": 10, "released_by": "nobody""#), "boards[0].tasks[0].released_by", "no task `nobody`"),
        (task(r#""name": "t", "priority": 1, "wcet_us": 1, "period_us": 10, "kind": "isr""#), "boards[0].tasks[0].kind", "unknown variant"),
        (r#"{ "can": { "frame_cost": "fast" } }"#.into(), "can.frame_cost", "thesis"),
        (r#"{ "can": { "messages": [ { "name": "m", "id": 5, "dlc": 9, "period_us": 10 } ] } }"#.into(), "can.messages[0].dlc", "8 data bytes"),
        (r#"{ "can": { "messages": [ { "name": "m", "id": 4096, "dlc": 1, "period_us": 10 } ] } }"#.into(), "can.messages[0].id", "11 bits"),
        (
            r#"{ "can": { "messages": [ { "name": "m", "id": 5, "dlc": 1, "period_us": 10 }, { "name": "n", "id": 5, "dlc": 1, "period_us": 10 } ] } }"#.into(),
            "can.messages[1].id",
            "already used by `m`",
        ),
        (
            r#"{ "can": { "messages": [ { "name": "m", "id": 5, "dlc": 1, "period_us": 10, "sender": "nowhere/t" } ] } }"#.into(),
            "can.messages[0].sender",
            "no board `nowhere`",
        ),
        (
            r#"{ "can": { "messages": [ { "name": "m", "id": 5, "dlc": 1, "period_us": 10, "sender": "no-slash" } ] } }"#.into(),
            "can.messages[0].sender",
            "board/task",
        ),
        (
            r#"{ "boards": [ { "name": "b", "tasks": [
                { "name": "x", "priority": 1, "wcet_us": 1, "period_us": 10, "released_by": "y" },
                { "name": "y", "priority": 1, "wcet_us": 1, "period_us": 10, "released_by": "x" } ] } ] }"#
                .into(),
            "released_by",
            "cycle",
        ),
        ("{ \"boards\": [ ".into(), "", "EOF"),
    ];
    for (json, path, problem) in cases {
        let message = error_of(&json);
        assert!(
            message.contains(path),
            "`{message}` does not name `{path}` (input {json})"
        );
        assert!(
            message.contains(problem),
            "`{message}` does not say `{problem}` (input {json})"
        );
    }
}

/// Issue 12: WCET 1e300 µs and period 1e17 µs saturated at ~584 years and the task came out "ok". Times beyond
/// the analysis's range are now refused, naming the field.
#[test]
fn saturating_times_are_refused_not_reported_schedulable() {
    let json = r#"{ "boards": [ { "name": "b", "tasks": [
        { "name": "t", "priority": 1, "wcet_us": 1e300, "period_us": 1e17 } ] } ] }"#;
    let message = error_of(json);
    assert!(message.contains("boards[0].tasks[0].wcet_us"), "{message}");
    assert!(message.contains("beyond the longest time"), "{message}");
    let json = r#"{ "boards": [ { "name": "b", "tasks": [
        { "name": "t", "priority": 1, "wcet_us": 1, "period_us": 1e17 } ] } ] }"#;
    assert!(error_of(json).contains("boards[0].tasks[0].period_us"));
    let json = r#"{ "can": { "frame_cost": 1e300, "messages": [] } }"#;
    assert!(error_of(json).contains("can.frame_cost"));
    assert!(FrameCostSpec::parse("1e300").is_err());
    // The largest accepted times still give an honest verdict: one task needing the whole processor and more.
    let json = r#"{ "boards": [ { "name": "b", "tasks": [
        { "name": "a", "priority": 2, "wcet_us": 1e12, "period_us": 1e12 },
        { "name": "t", "priority": 1, "wcet_us": 1e12, "period_us": 1e12 } ] } ] }"#;
    let system = Model::from_json(json)
        .and_then(|m| m.validate())
        .expect("in range");
    let a = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    assert!(!a.all_ok(), "{:?}", a.failures());
}

/// Issue 12: a 10^5-task model ran for minutes without output. Models beyond the benchmarked size are refused
/// with the limit named.
#[test]
fn oversized_models_are_refused_with_the_limit() {
    let tasks: Vec<String> = (0..=schedule_analysis::model::MAX_TASKS_PER_BOARD)
        .map(|i| {
            format!(r#"{{ "name": "t{i}", "priority": {i}, "wcet_us": 1, "period_us": 1000000 }}"#)
        })
        .collect();
    let json = format!(
        r#"{{ "boards": [ {{ "name": "b", "tasks": [ {} ] }} ] }}"#,
        tasks.join(",")
    );
    let message = error_of(&json);
    assert!(message.contains("boards[0].tasks"), "{message}");
    assert!(message.contains("at most 10000"), "{message}");
}
