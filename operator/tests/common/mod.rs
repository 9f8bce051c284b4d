//! What the `amiro` integration tests share.

/// Fails unless every one of `expected` appears in `text`, naming the one missing.
pub fn assert_mentions(text: &str, expected: &[&str]) {
    for wanted in expected {
        assert!(text.contains(wanted), "{wanted:?} missing from:\n{text}");
    }
}

/// The thesis's example command, `publish magnetometer-x every 900 µs at medium`: the frame `205#01840302`.
pub const THESIS_PUBLISH: [&str; 6] = [
    "publish",
    "magnetometer-x",
    "--every",
    "900us",
    "--priority",
    "medium",
];

/// `action` (`encode`, `send`) followed by [`THESIS_PUBLISH`].
pub fn thesis(action: &str) -> Vec<&str> {
    let mut args = vec![action];
    args.extend(THESIS_PUBLISH);
    args
}
