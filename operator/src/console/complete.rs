//! Tab completion of the console's command line: the flag forms from the same clap definition the scripts are
//! parsed with, the spoken forms from `speech`, and hints for values clap cannot list. Pure: a line in, the
//! completed line and what to tell the operator out.

use clap::CommandFactory;

use crate::script::StepLine;

/// The words the console itself understands, beside the script commands.
pub const CONSOLE_WORDS: [&str; 6] = ["clear", "dashboard", "help", "quit", "stop-driving", "menu"];

/// A completed command line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Completion {
    /// The command line after completion.
    pub input: String,
    /// What to show on the status line (the choices, or why nothing completes), if anything.
    pub status: Option<String>,
}

/// Completes the word at the end of `input`, or lists the choices.
pub fn complete(input: &str) -> Completion {
    let (before, current) = match input.rfind(' ') {
        Some(space) => (&input[..space], &input[space + 1..]),
        None => ("", input),
    };
    let words: Vec<&str> = before.split_whitespace().collect();
    let matching: Vec<String> = candidates(&words, current)
        .into_iter()
        .filter(|candidate| candidate.starts_with(current))
        .collect();
    let kept = &input[..input.len() - current.len()];
    match matching.as_slice() {
        [] => {
            let near =
                crate::speech::closest(current, candidates(&words, "").iter().map(String::as_str))
                    .map(|near| format!(": did you mean {near}?"))
                    .unwrap_or_default();
            Completion {
                input: input.to_string(),
                status: Some(format!("nothing completes {current:?}{near}")),
            }
        }
        [only] => Completion {
            input: format!("{kept}{only} "),
            status: None,
        },
        many => Completion {
            input: format!("{kept}{}", common_prefix(many)),
            status: Some(many.join("  ")),
        },
    }
}

fn common_prefix(words: &[String]) -> String {
    let first = &words[0];
    let mut length = first.len();
    for word in &words[1..] {
        length = first
            .char_indices()
            .zip(word.chars())
            .take_while(|((_, a), b)| a == b)
            .map(|((index, a), _)| index + a.len_utf8())
            .last()
            .unwrap_or(0)
            .min(length);
    }
    first[..length].to_string()
}

/// What may come next after `words`: the flag forms from the same clap definition the scripts are parsed with,
/// and the spoken forms (`publish gyroscope every 100ms at high`) from `speech`.
pub fn candidates(words: &[&str], current: &str) -> Vec<String> {
    let spoken = if current.starts_with('-') {
        Vec::new()
    } else {
        crate::speech::candidates(words)
    };
    let speaking = words.len() > 2
        && crate::speech::SPOKEN_COMMANDS.contains(&words[0])
        && !words.iter().any(|word| word.starts_with("--"));
    if speaking {
        return spoken;
    }
    let mut all = flag_candidates(words, current);
    for word in spoken {
        if !all.contains(&word) {
            all.push(word);
        }
    }
    all
}

fn flag_candidates(words: &[&str], current: &str) -> Vec<String> {
    let command = StepLine::command();
    let Some(first) = words.first() else {
        let mut names: Vec<String> = command
            .get_subcommands()
            .map(|sub| sub.get_name().to_string())
            .collect();
        names.extend(CONSOLE_WORDS.iter().map(|word| word.to_string()));
        names.sort();
        return names;
    };
    let Some(sub) = command.find_subcommand(first) else {
        return Vec::new();
    };
    let values_of = |arg: &clap::Arg| -> Vec<String> {
        let mut values: Vec<String> = arg
            .get_possible_values()
            .iter()
            .map(|value| value.get_name().to_string())
            .collect();
        if values.is_empty() {
            values = hints(arg.get_id().as_str());
        }
        values
    };
    // The value of the option just typed.
    if let Some(option) = words.last().and_then(|word| word.strip_prefix("--")) {
        if let Some(arg) = sub
            .get_arguments()
            .find(|arg| arg.get_long() == Some(option))
        {
            if arg.get_action().takes_values() {
                return values_of(arg);
            }
        }
    }
    let flags = || -> Vec<String> {
        sub.get_arguments()
            .filter_map(|arg| arg.get_long())
            .map(|long| format!("--{long}"))
            .filter(|flag| !words.contains(&flag.as_str()))
            .collect()
    };
    if current.starts_with('-') {
        return flags();
    }
    // Positionals fill in order; options with a value take the word after them.
    let mut filled = 0;
    let mut skip_value = false;
    for word in &words[1..] {
        if skip_value {
            skip_value = false;
        } else if word.starts_with("--") {
            skip_value = true;
        } else {
            filled += 1;
        }
    }
    let values = match sub.get_positionals().nth(filled) {
        Some(positional) => values_of(positional),
        None => flags(),
    };
    values
}

/// Suggestions for values clap cannot list (free text with a unit).
fn hints(id: &str) -> Vec<String> {
    let words: &[&str] = match id {
        "every" => &["10ms", "50ms", "62500us", "100ms", "250ms", "1s"],
        "forward" => &["50mm/s", "100mm/s", "-50mm/s", "0mm/s"],
        "turn" => &["30deg/s", "-30deg/s", "90deg/s", "0deg/s"],
        "duration" => &["1s", "2s", "3s"],
        "rgb" => &["255,0,0", "0,255,0", "0,0,255", "255,255,255", "0,0,0"],
        "priority" => &["urgent", "high", "medium", "low"],
        "led" => &["1", "2", "3", "4", "5", "6", "7", "8"],
        _ => &[],
    };
    words.iter().map(|word| word.to_string()).collect()
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_match_completes_the_word_many_list_themselves_none_suggests() {
        let one = complete("publish gyrosc");
        assert_eq!(one.input, "publish gyroscope ");
        assert_eq!(one.status, None);
        let many = complete("publish --every 10ms --pri");
        assert_eq!(many.input, "publish --every 10ms --priority ");
        let listed = complete("led 3 --rgb 255,");
        assert_eq!(listed.input, "led 3 --rgb 255,");
        assert!(listed.status.is_some_and(|s| s.contains("255,0,0")));
        let none = complete("publsh");
        assert_eq!(none.input, "publsh");
        assert!(none
            .status
            .is_some_and(|s| s.contains("did you mean publish")));
    }
}
