//! The thesis's Demo Sender as a menu (F2): questions and answers that build a command line.

use amiro_can::{Priority, TOPICS};

use crate::period::human_micros;

/// A question of the menu.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Question {
    /// Pick one of these.
    Choose {
        /// What is asked.
        prompt: &'static str,
        /// The answers to pick from.
        choices: Vec<String>,
    },
    /// Type a value (Enter alone takes the default).
    Type {
        /// What is asked.
        prompt: &'static str,
        /// Taken when nothing is typed.
        default: String,
    },
}

/// The thesis's Demo Sender as a menu: actuator or sensor, mode, topic, period, priority — building a command
/// line the operator can read, edit and send.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Menu {
    answers: Vec<String>,
    /// The highlighted choice.
    pub selected: usize,
    /// Text typed for a `Type` question.
    pub text: String,
}

fn priorities() -> Vec<String> {
    Priority::ALL
        .iter()
        .map(|priority| priority.name().to_string())
        .collect()
}

impl Menu {
    pub(super) fn answer(&mut self, answer: String) {
        self.answers.push(answer);
        self.selected = 0;
        self.text.clear();
    }

    /// The next question, or `None` when the command is complete.
    pub fn question(&self) -> Option<Question> {
        let answers: Vec<&str> = self.answers.iter().map(String::as_str).collect();
        let choose = |prompt, choices: Vec<String>| Some(Question::Choose { prompt, choices });
        let ask = |prompt, default: &str| {
            Some(Question::Type {
                prompt,
                default: default.to_string(),
            })
        };
        match answers.as_slice() {
            [] => choose(
                "Send a command to",
                vec!["sensor".into(), "motor".into(), "led".into()],
            ),
            ["sensor"] => choose("Mode", vec!["publish".into(), "once".into(), "stop".into()]),
            ["sensor", _] => choose(
                "Topic",
                TOPICS
                    .iter()
                    .filter(|info| info.is_sensor)
                    .map(|info| info.name.to_string())
                    .collect(),
            ),
            ["sensor", "publish", topic] => {
                let default = TOPICS
                    .iter()
                    .find(|info| info.name == *topic)
                    .map(|info| {
                        human_micros(u64::from(info.default_period_us)).replace([' ', 'µ'], "")
                    })
                    .unwrap_or_else(|| "50ms".into());
                ask("Period (e.g. 10ms, 900us, 1s)", &default)
            }
            ["sensor", "publish", _, _] | ["sensor", _, _] => choose("Priority", priorities()),
            ["motor"] => ask("Forward speed (e.g. 100mm/s, -50mm/s)", "100mm/s"),
            ["motor", _] => ask("Turn rate (e.g. 30deg/s, positive = left)", "0deg/s"),
            ["motor", _, _] => ask("For how long", "2s"),
            ["led"] => choose("LED", (1..=8).map(|led| led.to_string()).collect()),
            ["led", _] => ask("Colour R,G,B (0-255) or #RRGGBB", "255,0,0"),
            ["led", _, _] => choose("Priority", priorities()),
            _ => None,
        }
    }

    /// The command line the answers make.
    pub fn command(&self) -> String {
        let answers: Vec<&str> = self.answers.iter().map(String::as_str).collect();
        match answers.as_slice() {
            ["sensor", "publish", topic, every, priority] => {
                format!("publish {topic} --every {every} --priority {priority}")
            }
            ["sensor", mode, topic, priority] => format!("{mode} {topic} --priority {priority}"),
            ["motor", forward, turn, duration] => {
                format!("drive --forward {forward} --turn {turn} --for {duration}")
            }
            ["led", led, rgb, priority] => format!("led {led} --rgb '{rgb}' --priority {priority}"),
            _ => String::new(),
        }
    }
}
