//! Keeps `docs/protocol.md` and the code in agreement: its topic table must list exactly `TOPICS`, row by row.

use amiro_can::{TopicInfo, TOPICS};

const DOC: &str = include_str!("../../docs/protocol.md");

/// The table row the document must contain for `info`, as cells.
fn expected_cells(info: &TopicInfo) -> Vec<String> {
    vec![
        format!("0x{:02X}", info.topic.byte()),
        info.name.to_string(),
        info.board.name().to_string(),
        if info.is_sensor { "sensor" } else { "actuator" }.to_string(),
        info.dlc.to_string(),
        info.frames_per_sample.to_string(),
        if info.default_period_us == 0 {
            "—".to_string()
        } else {
            info.default_period_us.to_string()
        },
        info.layout.to_string(),
    ]
}

fn cells(row: &str) -> Vec<String> {
    let row = row.trim().trim_start_matches('|').trim_end_matches('|');
    row.split('|').map(|c| c.trim().to_string()).collect()
}

/// The rows between the table markers, without the header and the separator line.
fn doc_rows() -> Vec<Vec<String>> {
    let start = DOC
        .find("<!-- topic-table:begin -->")
        .expect("docs/protocol.md lacks the topic-table:begin marker");
    let end = DOC
        .find("<!-- topic-table:end -->")
        .expect("docs/protocol.md lacks the topic-table:end marker");
    assert!(start < end, "topic table markers are out of order");
    let table = &DOC[start..end];
    let mut lines = table
        .lines()
        .skip(1)
        .filter(|l| l.trim_start().starts_with('|'));
    let header = cells(lines.next().expect("topic table has no header"));
    assert_eq!(
        header,
        [
            "ID",
            "Name",
            "Board",
            "Role",
            "DLC",
            "Frames",
            "Default period (µs)",
            "Payload"
        ],
        "topic table header changed; update this test and the document together"
    );
    let separator = lines.next().expect("topic table has no separator line");
    assert!(cells(separator)
        .iter()
        .all(|c| c.chars().all(|ch| ch == '-' || ch == ':')));
    lines.map(cells).collect()
}

fn markdown_table() -> String {
    TOPICS
        .iter()
        .map(|info| format!("| {} |", expected_cells(info).join(" | ")))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn topic_table_matches_the_code() {
    let rows = doc_rows();
    let hint = format!("The rows the code implies are:\n{}", markdown_table());
    for (i, info) in TOPICS.iter().enumerate() {
        let expected = expected_cells(info);
        match rows.get(i) {
            Some(row) => assert_eq!(
                row,
                &expected,
                "docs/protocol.md topic row {} ({}) differs. {hint}",
                i + 1,
                info.name
            ),
            None => panic!(
                "docs/protocol.md topic table lacks {} and later rows. {hint}",
                info.name
            ),
        }
    }
    assert_eq!(
        rows.len(),
        TOPICS.len(),
        "docs/protocol.md lists topics the code does not have. {hint}"
    );
}

#[test]
fn the_thesis_example_is_documented() {
    assert!(DOC.contains("205#01840302"));
    assert!(DOC.contains("0x605"));
}

#[test]
fn every_error_reason_is_documented() {
    for kind in amiro_can::DecodeError::KINDS {
        assert!(
            DOC.contains(&format!("`{kind}`")),
            "docs/protocol.md does not explain `{kind}`"
        );
    }
}
