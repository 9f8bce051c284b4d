//! The whole protocol as a DBC file (`amiro dbc`), generated from amiro-can's topic table and signal layouts, so
//! CAN tools (cantools, python-can, SavvyCAN, Vector tools) decode the robot's frames the way `amiro` does.
//!
//! One message per identifier: for every topic and every priority the command (`<topic>_cmd_<priority>`, sent
//! by the `Operator` node) and, for sensors, the data (`<topic>_<priority>`, sent by the owning board). Pages
//! of multi-frame topics (diagnostics pages, proximity-ring sensors, command modes) are DBC multiplexing.

use std::fmt::Write as _;

use amiro_can::signals::{Mux, Signal};
use amiro_can::{Priority, Topic};

/// The node that sends commands.
const OPERATOR: &str = "Operator";

/// The DBC text.
pub fn generate() -> String {
    let mut out = String::new();
    out.push_str("VERSION \"amiro-can\"\n\nNS_ :\n\tCM_\n\tVAL_\n\nBS_:\n\n");
    out.push_str("BU_: Operator DiWheelDrive PowerManagement LightRing\n\n");
    let mut comments = String::new();
    let mut values = String::new();
    for topic in Topic::ALL {
        let info = topic.info();
        for priority in Priority::ALL {
            let command = topic.command_id(priority).raw();
            message(
                &mut out,
                command,
                &format!("{}_cmd_{}", ident(info.name), priority.name()),
                topic.command_dlc(),
                OPERATOR,
                info.board.name(),
                topic.command_signals(),
            );
            let what = if info.is_sensor {
                "stop (0) / publish (1, sample time) / once (2)".to_string()
            } else {
                info.layout.to_string()
            };
            let _ = writeln!(
                comments,
                "CM_ BO_ {command} \"{} command to {}, {} priority: {what}\";",
                info.name,
                info.board.name(),
                priority.name()
            );
            value_tables(&mut values, command, topic.command_signals());
            if info.is_sensor {
                let data = topic.data_id(priority).raw();
                message(
                    &mut out,
                    data,
                    &format!("{}_{}", ident(info.name), priority.name()),
                    info.dlc,
                    info.board.name(),
                    OPERATOR,
                    topic.data_signals(),
                );
                let _ = writeln!(
                    comments,
                    "CM_ BO_ {data} \"{} data from {}, {} priority, {} frame(s) per sample: {}\";",
                    info.name,
                    info.board.name(),
                    priority.name(),
                    info.frames_per_sample,
                    info.layout
                );
                value_tables(&mut values, data, topic.data_signals());
            }
        }
    }
    out.push_str(&comments);
    out.push('\n');
    out.push_str(&values);
    out
}

/// A DBC identifier from a topic name (`magnetometer-x` → `magnetometer_x`).
fn ident(name: &str) -> String {
    name.replace('-', "_")
}

fn message(
    out: &mut String,
    id: u16,
    name: &str,
    dlc: u8,
    sender: &str,
    receiver: &str,
    signals: &[Signal],
) {
    let _ = writeln!(out, "BO_ {id} {name}: {dlc} {sender}");
    for signal in signals {
        let mux = match signal.mux {
            Mux::Always => String::new(),
            Mux::Multiplexer => " M".to_string(),
            Mux::Page(page) => format!(" m{page}"),
        };
        let (min, max) = range(signal);
        let _ = writeln!(
            out,
            " SG_ {}{mux} : {}|{}@1{} ({},0) [{min}|{max}] \"{}\" {receiver}",
            signal.name,
            signal.start_bit,
            signal.bits,
            if signal.signed { '-' } else { '+' },
            signal.factor,
            signal.unit,
        );
    }
    out.push('\n');
}

/// The physical range of a signal, raw range times factor.
fn range(signal: &Signal) -> (String, String) {
    let bits = u32::from(signal.bits);
    let (raw_min, raw_max): (i128, i128) = if signal.signed {
        (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
    } else {
        (0, (1i128 << bits) - 1)
    };
    match signal.factor.parse::<i128>() {
        Ok(factor) => (
            (raw_min * factor).to_string(),
            (raw_max * factor).to_string(),
        ),
        // Every factor in the protocol is an integer today; a decimal one gets a float range.
        Err(_) => {
            let factor: f64 = signal.factor.parse().unwrap_or(1.0);
            (
                format!("{}", raw_min as f64 * factor),
                format!("{}", raw_max as f64 * factor),
            )
        }
    }
}

fn value_tables(out: &mut String, id: u16, signals: &[Signal]) {
    for signal in signals.iter().filter(|s| !s.choices.is_empty()) {
        let _ = write!(out, "VAL_ {id} {}", signal.name);
        for (value, name) in signal.choices {
            let _ = write!(out, " {value} \"{name}\"");
        }
        out.push_str(" ;\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_identifier_is_one_message() {
        let dbc = generate();
        let ids: Vec<u32> = dbc
            .lines()
            .filter_map(|l| l.strip_prefix("BO_ "))
            .map(|l| l.split(' ').next().unwrap().parse().unwrap())
            .collect();
        let sensors = Topic::ALL.iter().filter(|t| t.is_sensor()).count();
        assert_eq!(ids.len(), 4 * (Topic::ALL.len() + sensors));
        let mut unique = ids.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), ids.len(), "an identifier appears twice");
        // The thesis example's command and answer.
        assert!(dbc.contains("BO_ 517 magnetometer_x_cmd_medium: 4 Operator"));
        assert!(dbc.contains("BO_ 1541 magnetometer_x_medium: 4 DiWheelDrive"));
        assert!(dbc.contains(" SG_ x_um : 0|24@1- (100,0) [-838860800|838860700] \"um\" Operator"));
        assert!(dbc.contains(" SG_ page M : 0|8@1+ (1,0) [0|255] \"\" Operator"));
        assert!(dbc.contains(" SG_ wcrt_us m129 : 16|24@1+ (1,0) [0|16777215] \"us\" Operator"));
        assert!(dbc.contains("VAL_ 29 mode 1 \"hibernate\" 2 \"deep-sleep\""));
    }
}
