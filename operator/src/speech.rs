//! Commands that read like speech, beside the flag forms: `publish gyroscope every 100ms at high`,
//! `once floor at urgent`, `stop gyroscope`, `led 3 red`, `led 3 #FF8020`, `drive 100mm/s turn 30deg/s for 3s`.
//!
//! A spoken line is rewritten word by word into the flag form (`publish gyroscope --every 100ms --priority high`)
//! and then parsed by the one clap definition scripts and the console share, so both forms always mean the same
//! frame. Topic names may be shortened to any unambiguous beginning (`gyro`, `floor`, `ring`), and a word that is
//! almost a known one gets a suggestion ("did you mean magnetometer-x?").

use amiro_can::{Priority, TOPICS};
use anyhow::{bail, Result};

/// The command words the spoken grammar knows.
pub const SPOKEN_COMMANDS: [&str; 5] = ["publish", "once", "stop", "led", "drive"];

/// The priority a spoken sensor command (`publish`, `once`, `stop`) uses without `at PRIORITY`.
pub const DEFAULT_SENSOR_PRIORITY: Priority = Priority::Medium;

/// Colour names for `led N COLOUR`, with their 8-bit red, green and blue.
pub const COLOURS: [(&str, [u8; 3]); 12] = [
    ("red", [255, 0, 0]),
    ("green", [0, 255, 0]),
    ("blue", [0, 0, 255]),
    ("white", [255, 255, 255]),
    ("yellow", [255, 255, 0]),
    ("orange", [255, 128, 0]),
    ("cyan", [0, 255, 255]),
    ("magenta", [255, 0, 255]),
    ("purple", [128, 0, 255]),
    ("pink", [255, 105, 180]),
    ("off", [0, 0, 0]),
    ("black", [0, 0, 0]),
];

/// Short names that are not a beginning of the topic's name.
const ALIASES: [(&str, &str); 3] = [
    ("ring", "proximity-ring"),
    ("floor", "floor-proximity"),
    ("battery", "power-status"),
];

/// The sensor topics' names, in table order.
pub fn sensor_topics() -> impl Iterator<Item = &'static str> {
    TOPICS
        .iter()
        .filter(|info| info.is_sensor)
        .map(|info| info.name)
}

/// If `words` are a spoken command, the same command in flag form; `None` when they are in flag form already
/// (or are not a command this grammar knows), so clap reads them as they are.
pub fn translate(words: &[String]) -> Option<Result<Vec<String>>> {
    let (first, rest) = words.split_first()?;
    if rest.is_empty() || words.iter().any(|word| word.starts_with("--")) {
        return None;
    }
    Some(match first.as_str() {
        "publish" | "once" | "stop" => sensor_command(first, rest),
        "led" => led(rest),
        "drive" => drive(rest),
        _ => return None,
    })
}

/// The topic a spoken word names: its full name, an alias, or the one sensor topic it begins.
pub fn resolve_topic(word: &str) -> Result<&'static str> {
    let word = word.to_ascii_lowercase();
    if let Some(name) = sensor_topics().find(|name| *name == word) {
        return Ok(name);
    }
    if let Some((_, name)) = ALIASES.iter().find(|(alias, _)| *alias == word) {
        return Ok(name);
    }
    let beginning: Vec<&str> = sensor_topics()
        .filter(|name| name.starts_with(word.as_str()))
        .collect();
    match beginning.as_slice() {
        [one] => Ok(one),
        [] => bail!("unknown topic {word:?}{}", hint(&word, sensor_topics())),
        many => bail!("{word:?} could be {}: say which", many.join(", ")),
    }
}

fn priority(word: Option<&String>) -> Result<Priority> {
    let Some(word) = word else {
        bail!("`at` needs a priority: urgent, high, medium or low");
    };
    Priority::from_name(&word.to_ascii_lowercase()).ok_or_else(|| {
        anyhow::anyhow!(
            "unknown priority {word:?}{}; the priorities are urgent, high, medium and low",
            hint(word, Priority::ALL.iter().map(|p| p.name()))
        )
    })
}

/// Takes a value that may be written as two words (`100 ms`) as one (`100ms`).
fn value(words: &[String], at: &mut usize, units: &[&str]) -> Option<String> {
    let first = words.get(*at)?.clone();
    *at += 1;
    if first.parse::<f64>().is_ok() {
        if let Some(unit) = words.get(*at).filter(|unit| units.contains(&unit.as_str())) {
            *at += 1;
            return Some(format!("{first}{unit}"));
        }
    }
    Some(first)
}

const TIME_UNITS: [&str; 4] = ["us", "µs", "ms", "s"];
const SPEED_UNITS: [&str; 5] = ["um/s", "µm/s", "mm/s", "cm/s", "m/s"];
const TURN_UNITS: [&str; 6] = ["urad/s", "µrad/s", "mrad/s", "rad/s", "deg/s", "°/s"];

/// `publish TOPIC [every PERIOD] [at PRIORITY]`, `once TOPIC [at PRIORITY]`, `stop TOPIC [at PRIORITY]`.
fn sensor_command(command: &str, rest: &[String]) -> Result<Vec<String>> {
    let topic = resolve_topic(&rest[0])?;
    let mut every = None;
    let mut at = None;
    let mut index = 1;
    let keywords: &[&str] = if command == "publish" {
        &["every", "at"]
    } else {
        &["at"]
    };
    while let Some(word) = rest.get(index) {
        index += 1;
        match word.as_str() {
            "every" if command == "publish" => {
                every =
                    Some(value(rest, &mut index, &TIME_UNITS).ok_or_else(|| {
                        anyhow::anyhow!("`every` needs a period, e.g. every 100ms")
                    })?);
            }
            "at" => {
                // `at high`, `at high priority`, `at priority high`.
                if rest.get(index).map(String::as_str) == Some("priority") {
                    index += 1;
                }
                at = Some(priority(rest.get(index))?);
                index += 1;
                if rest.get(index).map(String::as_str) == Some("priority") {
                    index += 1;
                }
            }
            other => bail!(
                "unexpected {other:?} after `{command} {topic}`{}; say {}",
                hint(other, keywords.iter().copied()),
                expected(command)
            ),
        }
    }
    let priority = at.unwrap_or(DEFAULT_SENSOR_PRIORITY);
    let mut flags = vec![command.to_string(), topic.to_string()];
    if command == "publish" {
        let every = match every {
            Some(every) => every,
            // The topic's natural period, as the menu offers it.
            None => TOPICS
                .iter()
                .find(|info| info.name == topic)
                .map(|info| format!("{}us", info.default_period_us))
                .unwrap_or_else(|| "50ms".into()),
        };
        flags.extend(["--every".into(), every]);
    }
    flags.extend(["--priority".into(), priority.name().into()]);
    Ok(flags)
}

fn expected(command: &str) -> &'static str {
    match command {
        "publish" => "e.g. `publish gyroscope every 100ms at high`",
        "once" => "e.g. `once floor at urgent`",
        _ => "e.g. `stop gyroscope` or `stop gyroscope at high`",
    }
}

/// `led N COLOUR [at PRIORITY]`: a colour name, `#RRGGBB` or `R,G,B`.
fn led(rest: &[String]) -> Result<Vec<String>> {
    let led = &rest[0];
    let Some(colour) = rest.get(1) else {
        bail!("which colour? e.g. `led {led} red` or `led {led} #FF8020`");
    };
    let rgb = if colour.starts_with('#') || colour.contains(',') {
        colour.clone()
    } else if let Some((_, [r, g, b])) = COLOURS
        .iter()
        .find(|(name, _)| name.eq_ignore_ascii_case(colour))
    {
        format!("{r},{g},{b}")
    } else {
        bail!(
            "unknown colour {colour:?}{}; say a name ({}), #RRGGBB or R,G,B",
            hint(colour, COLOURS.iter().map(|(name, _)| *name)),
            COLOURS.map(|(name, _)| name).join(", ")
        );
    };
    let mut flags = vec!["led".into(), led.clone(), "--rgb".into(), rgb];
    match rest.get(2).map(String::as_str) {
        None => {}
        Some("at") => {
            flags.extend(["--priority".into(), priority(rest.get(3))?.name().into()]);
            if let Some(extra) = rest.get(4).filter(|word| *word != "priority") {
                bail!("unexpected {extra:?} after the priority");
            }
        }
        Some(other) => bail!(
            "unexpected {other:?} after the colour{}; say e.g. `led {led} red at high`",
            hint(other, ["at"])
        ),
    }
    Ok(flags)
}

/// `drive [forward|backward] SPEED [turn [left|right] RATE] [for DURATION] [every PERIOD] [at PRIORITY]`.
fn drive(rest: &[String]) -> Result<Vec<String>> {
    let mut flags = vec!["drive".to_string()];
    let mut index = 0;
    const KEYWORDS: [&str; 6] = ["forward", "backward", "turn", "for", "every", "at"];
    while let Some(word) = rest.get(index) {
        index += 1;
        let negate = |text: String| match text.strip_prefix('-') {
            Some(positive) => positive.to_string(),
            None => format!("-{text}"),
        };
        match word.as_str() {
            "forward" | "ahead" | "backward" | "backwards" | "back" => {
                let speed = value(rest, &mut index, &SPEED_UNITS).ok_or_else(|| {
                    anyhow::anyhow!("`{word}` needs a speed, e.g. {word} 100mm/s")
                })?;
                let speed = if word.starts_with("back") {
                    negate(speed)
                } else {
                    speed
                };
                flags.extend(["--forward".into(), speed]);
            }
            "turn" | "turning" => {
                let mut right = false;
                match rest.get(index).map(String::as_str) {
                    Some("left") => index += 1,
                    Some("right") => {
                        right = true;
                        index += 1;
                    }
                    _ => {}
                }
                let rate = value(rest, &mut index, &TURN_UNITS).ok_or_else(|| {
                    anyhow::anyhow!(
                        "`turn` needs a rate, e.g. turn 30deg/s (positive: to the left)"
                    )
                })?;
                flags.extend(["--turn".into(), if right { negate(rate) } else { rate }]);
            }
            "for" => {
                let duration = value(rest, &mut index, &TIME_UNITS)
                    .ok_or_else(|| anyhow::anyhow!("`for` needs a duration, e.g. for 3s"))?;
                flags.extend(["--for".into(), duration]);
            }
            "every" => {
                let every = value(rest, &mut index, &TIME_UNITS)
                    .ok_or_else(|| anyhow::anyhow!("`every` needs a period, e.g. every 200ms"))?;
                flags.extend(["--every".into(), every]);
            }
            "at" => {
                flags.extend([
                    "--priority".into(),
                    priority(rest.get(index))?.name().into(),
                ]);
                index += 1;
            }
            _ => {
                // A bare speed: `drive 100mm/s …`.
                index -= 1;
                let speed = value(rest, &mut index, &SPEED_UNITS).unwrap_or_default();
                if !SPEED_UNITS.iter().any(|unit| speed.ends_with(unit)) {
                    bail!(
                        "unexpected {speed:?} in drive{}; say e.g. `drive 100mm/s turn 30deg/s for 3s`",
                        hint(&speed, KEYWORDS)
                    );
                }
                flags.extend(["--forward".into(), speed]);
            }
        }
    }
    Ok(flags)
}

/// `; did you mean X?` when `word` is close to one of `known`, else nothing.
pub fn hint<'a>(word: &str, known: impl IntoIterator<Item = &'a str>) -> String {
    match closest(word, known) {
        Some(near) => format!("; did you mean {near}?"),
        None => String::new(),
    }
}

/// The known word closest to `word`, if it is close enough to be a typo of it (a few letters off, or swapped).
pub fn closest<'a>(word: &str, known: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let word = word.to_ascii_lowercase();
    let allowed = (word.chars().count() / 3).clamp(1, 3);
    known
        .into_iter()
        .map(|candidate| (edit_distance(&word, candidate), candidate))
        .filter(|(distance, _)| *distance > 0 && *distance <= allowed)
        .min_by_key(|(distance, _)| *distance)
        .map(|(_, candidate)| candidate)
}

/// The optimal-string-alignment distance: insertions, deletions, substitutions and swaps of neighbours.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut rows = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in rows.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in rows[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (rows[i - 1][j] + 1)
                .min(rows[i][j - 1] + 1)
                .min(rows[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(rows[i - 2][j - 2] + 1);
            }
            rows[i][j] = best;
        }
    }
    rows[a.len()][b.len()]
}

/// Every word a command line may contain that is not a number: commands, topics, priorities, keywords, colours.
fn vocabulary() -> Vec<&'static str> {
    let mut words: Vec<&'static str> = TOPICS.iter().map(|info| info.name).collect();
    words.extend(Priority::ALL.iter().map(|p| p.name()));
    words.extend(SPOKEN_COMMANDS);
    words.extend(["motor", "wait", "shutdown", "policy", "stop-driving"]);
    words.extend([
        "every", "at", "turn", "for", "forward", "backward", "left", "right",
    ]);
    words.extend(COLOURS.iter().map(|(name, _)| *name));
    words
}

/// For a line clap could not read: the first word that looks like a typo of a known word, as a suggestion.
pub fn suggestion(words: &[String]) -> Option<String> {
    let known = vocabulary();
    words
        .iter()
        .filter(|word| !word.starts_with('-') && !word.starts_with(|c: char| c.is_ascii_digit()))
        .filter(|word| !known.contains(&word.as_str()))
        .find_map(|word| closest(word, known.iter().copied()).map(|near| (word, near)))
        .map(|(word, near)| format!("{word:?}: did you mean {near}?"))
}

/// What Tab may offer after `words` in the spoken grammar (the flag forms come from clap).
pub fn candidates(words: &[&str]) -> Vec<String> {
    let strings = |list: &[&str]| list.iter().map(|word| word.to_string()).collect::<Vec<_>>();
    let priorities = || strings(&Priority::ALL.map(|p| p.name()));
    let Some((first, rest)) = words.split_first() else {
        return Vec::new();
    };
    if words.iter().any(|word| word.starts_with("--")) {
        return Vec::new();
    }
    let last = rest.last().copied();
    match (*first, last) {
        (_, Some("at")) => priorities(),
        ("publish", Some("every")) => strings(&["10ms", "50ms", "100ms", "250ms", "1s"]),
        ("publish" | "once" | "stop", Some(_)) => {
            let mut next = Vec::new();
            if *first == "publish" && !rest.contains(&"every") {
                next.push("every".to_string());
            }
            if !rest.contains(&"at") {
                next.push("at".to_string());
            }
            next
        }
        ("publish" | "once" | "stop", None) => sensor_topics()
            .chain(ALIASES.iter().map(|(alias, _)| *alias))
            .map(str::to_string)
            .collect(),
        ("led", Some(_)) if rest.len() == 1 => {
            let mut colours = strings(&COLOURS.map(|(name, _)| name));
            colours.push("#FF8020".into());
            colours
        }
        ("led", Some(_)) if rest.len() == 2 => strings(&["at"]),
        ("drive", Some("turn")) => strings(&["30deg/s", "-30deg/s", "90deg/s", "left", "right"]),
        ("drive", Some("left" | "right")) => strings(&["30deg/s", "90deg/s"]),
        ("drive", Some("for")) => strings(&["1s", "2s", "3s"]),
        ("drive", Some("every")) => strings(&["100ms", "200ms"]),
        ("drive", Some("forward" | "backward")) => strings(&["50mm/s", "100mm/s", "200mm/s"]),
        ("drive", _) => {
            let mut next: Vec<String> = Vec::new();
            let said_speed = rest
                .iter()
                .any(|word| word.ends_with("/s") && !word.contains("rad") && !word.contains("deg"));
            if !said_speed {
                next.extend(strings(&["100mm/s", "50mm/s", "forward", "backward"]));
            }
            for keyword in ["turn", "for", "every", "at"] {
                if !rest.contains(&keyword) {
                    next.push(keyword.into());
                }
            }
            next
        }
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::script::{parse_step, Step};

    fn flags(line: &str) -> Result<String> {
        let words: Vec<String> = line.split_whitespace().map(str::to_string).collect();
        translate(&words)
            .expect("a spoken line")
            .map(|words| words.join(" "))
    }

    fn frames(line: &str) -> Vec<String> {
        match parse_step(line, false) {
            Ok(Some(Step::Send(frames))) => frames.iter().map(ToString::to_string).collect(),
            other => panic!("{line}: {other:?}"),
        }
    }

    #[test]
    fn the_issues_sentences_send_the_same_frames_as_the_flag_forms() {
        for (spoken, flagged) in [
            (
                "publish gyroscope every 100ms at high",
                "publish gyroscope --every 100ms --priority high",
            ),
            (
                "once floor at urgent",
                "once floor-proximity --priority urgent",
            ),
            ("stop gyroscope", "stop gyroscope --priority medium"),
            ("led 3 red", "led 3 --rgb 255,0,0"),
            ("led 3 #FF8020", "led 3 --rgb #FF8020"),
            (
                "publish magnetometer-x every 900 us at medium priority",
                "publish magnetometer-x --every 900us --priority medium",
            ),
            (
                "led 5 orange at high",
                "led 5 --rgb 255,128,0 --priority high",
            ),
        ] {
            assert_eq!(frames(spoken), frames(flagged), "{spoken}");
        }
        assert_eq!(
            frames("publish gyroscope every 100ms at high"),
            ["108#01640000"]
        );
        assert_eq!(frames("once floor at urgent"), ["004#02"]);
        assert_eq!(frames("stop gyroscope"), ["208#00"]);
        assert_eq!(frames("led 3 red"), ["313#FF0000"]);
        assert_eq!(frames("led 3 #FF8020"), ["313#FF8020"]);
        assert_eq!(frames("stop ring at low"), ["31F#00"]);
    }

    #[test]
    fn a_publish_without_a_period_uses_the_topics_natural_one() {
        // proximity-ring runs every 62.5 ms by default.
        assert_eq!(
            frames("publish ring"),
            frames("publish proximity-ring --every 62500us --priority medium")
        );
    }

    #[test]
    fn spoken_drives_become_the_same_plans() {
        let plan = |line: &str| match parse_step(line, false) {
            Ok(Some(Step::Drive(plan))) => plan,
            other => panic!("{line}: {other:?}"),
        };
        let spoken = plan("drive 100mm/s turn 30deg/s for 3s");
        let flagged = plan("drive --forward 100mm/s --turn 30deg/s --for 3s");
        assert_eq!(spoken.command, flagged.command);
        assert_eq!(spoken.duration, flagged.duration);
        assert_eq!(spoken.command.velocity_um_s, 100_000);
        assert_eq!(spoken.command.angular_urad_s, 523_599);
        let back = plan("drive backward 50 mm/s turn right 30 deg/s for 2 s at urgent");
        assert_eq!(back.command.velocity_um_s, -50_000);
        assert_eq!(back.command.angular_urad_s, -523_599);
        assert_eq!(back.priority, Priority::Urgent);
        assert_eq!(plan("drive turn 90deg/s for 1s").command.velocity_um_s, 0);
    }

    #[test]
    fn misspelt_words_get_a_suggestion() {
        let error = format!("{:#}", flags("publish magnetomter-x every 1s").unwrap_err());
        assert!(error.contains("did you mean magnetometer-x?"), "{error}");
        let error = format!("{:#}", flags("publish gyroscope evry 100ms").unwrap_err());
        assert!(error.contains("did you mean every?"), "{error}");
        let error = format!("{:#}", flags("once floor at urgnet").unwrap_err());
        assert!(error.contains("did you mean urgent?"), "{error}");
        let error = format!("{:#}", flags("led 3 rde").unwrap_err());
        assert!(error.contains("did you mean red?"), "{error}");
        let error = format!("{:#}", flags("stop magnetometer").unwrap_err());
        assert!(
            error.contains("magnetometer-x, magnetometer-y, magnetometer-z"),
            "{error}"
        );
        // In flag form and for a misspelt command, the step parser adds the suggestion to clap's message.
        let error = format!(
            "{:#}",
            parse_step("pubish gyroscope every 10ms", false).unwrap_err()
        );
        assert!(error.contains("did you mean publish?"), "{error}");
        let error = format!(
            "{:#}",
            parse_step("publish magnetometer-z --every 10ms --priority hihg", false).unwrap_err()
        );
        assert!(error.contains("did you mean high?"), "{error}");
        assert_eq!(
            closest("xyzzy", vocabulary()),
            None,
            "nothing near: no guess"
        );
    }

    #[test]
    fn distances_count_swaps_as_one_edit() {
        assert_eq!(edit_distance("gyroscope", "gyroscope"), 0);
        assert_eq!(edit_distance("gyorscope", "gyroscope"), 1);
        assert_eq!(edit_distance("gyrscope", "gyroscope"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
    }

    #[test]
    fn flag_forms_and_other_steps_are_left_to_clap() {
        let words = |line: &str| {
            line.split_whitespace()
                .map(str::to_string)
                .collect::<Vec<_>>()
        };
        assert!(translate(&words("stop gyroscope --priority high")).is_none());
        assert!(translate(&words("wait 1s")).is_none());
        assert!(translate(&words("drive")).is_none());
        assert!(translate(&words("205#01840302")).is_none());
    }
}
