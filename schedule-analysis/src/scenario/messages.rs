//! The bus's messages: one per published topic (sent by its publisher job) and one per command stream (ending
//! at the board's command handler).

use amiro_can::{CanId, Kind};

use super::board::Ends;
use super::plan::Plan;
use super::{board_folder, Scenario};
use crate::model::MessageModel;

/// The messages of the planned topics, sensors first; a warning per command whose board has no command handler.
pub(super) fn messages(
    scenario: &Scenario,
    plan: &Plan,
    ends: &Ends,
    warnings: &mut Vec<String>,
) -> Vec<MessageModel> {
    let mut messages = Vec::new();
    for p in &plan.sensors {
        let Some(entry) = scenario.publishers.get(p.index) else {
            continue;
        };
        messages.push(MessageModel {
            name: p.info.name.to_string(),
            id: u32::from(CanId::new(Kind::Sensor, p.priority, p.info.topic.byte()).raw()),
            dlc: p.info.dlc,
            period_us: entry.period_us,
            deadline_us: entry.deadline_us,
            jitter_us: 0.0,
            sender: ends.senders.get(&p.info.topic).cloned(),
            receiver: None,
            frames: u32::from(p.info.frames_per_sample.max(1)),
            extended: false,
            jitter_budget_us: entry.jitter_budget_us,
            e2e_deadline_us: None,
        });
    }
    for p in &plan.commands {
        let Some(entry) = scenario.commands.get(p.index) else {
            continue;
        };
        let board = board_folder(p.info.board);
        let receiver = ends.receivers.get(board).cloned();
        if receiver.is_none() {
            warnings.push(format!(
                "command `{}`: board `{board}` names no command_handler, so its path ends on the bus",
                p.info.name
            ));
        }
        messages.push(MessageModel {
            name: p.info.name.to_string(),
            id: u32::from(CanId::new(Kind::Command, p.priority, p.info.topic.byte()).raw()),
            dlc: p.info.dlc,
            period_us: entry.period_us,
            deadline_us: entry.deadline_us,
            jitter_us: entry.jitter_us,
            sender: None,
            receiver,
            frames: 1,
            extended: false,
            jitter_budget_us: entry.jitter_budget_us,
            e2e_deadline_us: None,
        });
    }
    messages
}
