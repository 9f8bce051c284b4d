//! How the dashboard is drawn: the topic table and the boards' lines, with ratatui, into any frame or a text
//! buffer (tests and a terminal that is not one).

use std::collections::VecDeque;

use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Borders, Paragraph, Row, Table, Wrap};

use amiro_can::Board;

use super::{board_of, short_board, Dashboard};

impl Dashboard {
    /// Draws the dashboard into `area`.
    pub fn render(&self, frame: &mut ratatui::Frame<'_>, area: Rect) {
        let board_lines = self.board_lines();
        // Each line wraps onto as many rows as it needs; the topics keep at least half the height.
        let inner = usize::from(area.width.saturating_sub(2)).max(1);
        let wrapped: usize = board_lines
            .iter()
            .map(|line| line.chars().count().div_ceil(inner).max(1))
            .sum();
        let health_height = (wrapped as u16 + 2).min(area.height / 2);
        let [table_area, health_area] =
            Layout::vertical([Constraint::Min(3), Constraint::Length(health_height)]).areas(area);
        let header = Row::new([
            "topic",
            "bd",
            "prio",
            "latest",
            "period ms",
            "late/mis",
            "trend",
            "verdict",
        ])
        .style(Style::default().add_modifier(Modifier::BOLD));
        let rows: Vec<Row<'_>> = self
            .rows
            .values()
            .map(|(topic, row)| {
                let board = board_of(*topic).map_or("", short_board);
                let measured = (!row.intervals.is_empty())
                    .then(|| row.intervals.iter().sum::<u64>() / row.intervals.len() as u64);
                let period = format!(
                    "{}/{}",
                    measured.map_or("-".into(), milliseconds),
                    row.requested_us.map_or("-".into(), milliseconds)
                );
                let late = if row.requested_us.is_some() {
                    format!("{}/{}", row.late, row.missing + self.overdue(row))
                } else {
                    "-".into()
                };
                Row::new([
                    topic.name().to_string(),
                    board.to_string(),
                    row.priority.map_or("", |p| p.name()).to_string(),
                    row.latest.clone(),
                    period,
                    late,
                    sparkline(&row.history),
                    row.verdict.unwrap_or("").to_string(),
                ])
            })
            .collect();
        let empty = rows.is_empty();
        let table = Table::new(
            rows,
            [
                Constraint::Length(14),
                Constraint::Length(3),
                Constraint::Length(6),
                Constraint::Length(18),
                Constraint::Length(9),
                Constraint::Length(8),
                Constraint::Length(6),
                Constraint::Min(7),
            ],
        )
        .header(header)
        .block(Block::default().borders(Borders::ALL).title(if empty {
            " topics (nothing heard yet) "
        } else {
            " topics "
        }));
        frame.render_widget(table, table_area);
        let lines: Vec<Line<'_>> = board_lines.into_iter().map(Line::raw).collect();
        frame.render_widget(
            Paragraph::new(lines).wrap(Wrap { trim: false }).block(
                Block::default()
                    .borders(Borders::ALL)
                    .title(" boards (their diagnostics: amiro health asks) "),
            ),
            health_area,
        );
    }

    /// Each board's health, and the last admission verdict it sent, one line each.
    fn board_lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        for board in Board::ALL {
            let topic = board.diagnostics_topic().byte();
            lines.push(
                self.health
                    .get(&topic)
                    .map(|(_, health)| health.verdict(board))
                    .unwrap_or_else(|| format!("{board}: no diagnostics heard")),
            );
            if let Some(verdict) = self.verdicts.get(&topic) {
                lines.push(format!("  last verdict: {verdict}"));
            }
        }
        lines
    }

    /// The dashboard drawn on a `width`×`height` screen, as text (for a capture or a terminal that is not one).
    pub fn text(&self, width: u16, height: u16) -> String {
        let backend = ratatui::backend::TestBackend::new(width, height);
        let Ok(mut terminal) = ratatui::Terminal::new(backend) else {
            return String::new();
        };
        if terminal
            .draw(|frame| self.render(frame, frame.area()))
            .is_err()
        {
            return String::new();
        }
        buffer_text(terminal.backend().buffer())
    }
}

/// The characters of a buffer, one line per row, trailing blanks removed.
pub fn buffer_text(buffer: &ratatui::buffer::Buffer) -> String {
    let width = usize::from(buffer.area.width);
    let mut text = String::new();
    for row in buffer.content.chunks(width.max(1)) {
        let line: String = row.iter().map(|cell| cell.symbol()).collect();
        text.push_str(line.trim_end());
        text.push('\n');
    }
    text
}

/// µs as milliseconds: `100`, `62.5`, `0.9`, `0.001`.
fn milliseconds(micros: u64) -> String {
    let ms = micros as f64 / 1000.0;
    if micros < 1000 {
        return format!("{ms:.3}").trim_end_matches('0').to_string();
    }
    if ms >= 100.0 || (ms - ms.round()).abs() < 0.05 {
        format!("{ms:.0}")
    } else {
        format!("{ms:.1}")
    }
}

/// The values as bars from the lowest to the highest of them.
fn sparkline(values: &VecDeque<f64>) -> String {
    const BARS: [char; 8] = ['▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let low = values.iter().copied().fold(f64::INFINITY, f64::min);
    let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    values
        .iter()
        .map(|value| {
            if high > low {
                BARS[(((value - low) / (high - low)) * 7.0).round() as usize]
            } else {
                BARS[3]
            }
        })
        .collect()
}
