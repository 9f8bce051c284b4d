//! Checks that DiWheelDrive's publisher tasks carry the RTIC priorities `levels.rs` assigns.
//!
//! RTIC needs literal priorities in its task attributes, while the firmware's CAN → RTIC mapping
//! lives in `diwheeldrive/src/levels.rs`; this test keeps the two from drifting apart.
#[cfg(test)]
mod tests {
    use std::path::Path;

    use schedule_analysis::rtic_source::parse_app;

    fn level_const(source: &str, name: &str) -> u8 {
        let needle = format!("pub const {name}: u8 = ");
        let start = source
            .find(&needle)
            .unwrap_or_else(|| panic!("levels.rs has no {name}"))
            + needle.len();
        let end = source[start..].find(';').expect("constant ends with `;`") + start;
        source[start..end].trim().parse().expect("a u8 literal")
    }

    #[test]
    fn publisher_priorities_follow_levels() {
        let fw = Path::new(env!("CARGO_MANIFEST_DIR")).join("../diwheeldrive/src");
        let app = parse_app(&std::fs::read_to_string(fw.join("main.rs")).unwrap()).unwrap();
        let levels = std::fs::read_to_string(fw.join("levels.rs")).unwrap();
        for (task, constant) in [
            ("publish_urgent", "PUBLISH_URGENT"),
            ("publish_high", "PUBLISH_HIGH"),
            ("publish_medium", "PUBLISH_MEDIUM"),
            ("publish_low", "PUBLISH_LOW"),
            ("handle_commands", "CONTROL"),
            ("motor_control", "MOTOR_CONTROL"),
            ("shutdown_sequence", "SHUTDOWN_SEQUENCE"),
            ("can_rx", "CAN_RX"),
            ("can_tx", "CAN_TX"),
            ("shutdown", "SHUTDOWN"),
        ] {
            let declared = app
                .task(task)
                .unwrap_or_else(|| panic!("no task {task}"))
                .priority;
            assert_eq!(
                declared,
                level_const(&levels, constant),
                "{task} must run at levels::{constant}"
            );
        }
    }
}
