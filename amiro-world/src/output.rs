//! What people look at after a run: the trajectory as CSV (`t_s,x_m,y_m,heading_deg`, one row
//! per controller tick) and an SVG of the arena with the path drawn over it.

use std::fmt::Write as _;
use std::io::{self, Write};

use crate::file::{Arena, FloorShape, Pose, BODY_RADIUS_M};
use crate::geometry::Vec2;
use crate::motion::wrap;

/// One row of the trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Virtual time, µs.
    pub t_us: u64,
    /// The pose then.
    pub pose: Pose,
}

/// The robot's path, sampled.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// The samples in time order.
    pub samples: Vec<Sample>,
}

/// The CSV header row.
pub const CSV_HEADER: &str = "t_s,x_m,y_m,heading_deg";

/// Why a trajectory CSV could not be read back.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CsvError {
    /// The first line is not [`CSV_HEADER`].
    #[error("line 1: the header is {0:?}, expected \"{CSV_HEADER}\"")]
    Header(String),
    /// A row that is not four numbers of the written form.
    #[error("line {line}: {reason}")]
    Row {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// `S.UUUUUU` (up to six decimals, non-negative) as µs.
fn parse_time_us(text: &str) -> Option<u64> {
    let (whole, fraction) = text.split_once('.').unwrap_or((text, ""));
    if whole.is_empty()
        || fraction.len() > 6
        || !whole
            .bytes()
            .chain(fraction.bytes())
            .all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let micros = format!("{fraction:0<6}").parse::<u64>().ok()?;
    whole
        .parse::<u64>()
        .ok()?
        .checked_mul(1_000_000)?
        .checked_add(micros)
}

impl Trajectory {
    /// Adds the pose at `t_us`.
    pub fn record(&mut self, t_us: u64, pose: Pose) {
        self.samples.push(Sample { t_us, pose });
    }

    /// One CSV row: time to the µs, position to the µm, heading to a thousandth of a degree
    /// in (−180, 180].
    pub fn csv_row(sample: &Sample) -> String {
        format!(
            "{}.{:06},{:.6},{:.6},{:.3}",
            sample.t_us / 1_000_000,
            sample.t_us % 1_000_000,
            sample.pose.position.x,
            sample.pose.position.y,
            wrap(sample.pose.heading).to_degrees()
        )
    }

    /// Reads back what [`Trajectory::write_csv`] wrote (rows in time order; blank lines
    /// ignored).
    pub fn read_csv(text: &str) -> Result<Trajectory, CsvError> {
        let mut lines = text.lines().enumerate();
        let header = lines.next().map_or("", |(_, l)| l.trim());
        if header != CSV_HEADER {
            return Err(CsvError::Header(header.to_string()));
        }
        let mut trajectory = Trajectory::default();
        for (k, line) in lines {
            let row = |reason: String| CsvError::Row {
                line: k + 1,
                reason,
            };
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').collect();
            let [t, x, y, heading] = fields[..] else {
                return Err(row(format!("{} fields, expected 4", fields.len())));
            };
            let t_us = parse_time_us(t)
                .ok_or_else(|| row(format!("t_s {t:?} is not a time in seconds")))?;
            let number = |name: &str, text: &str| {
                text.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| row(format!("{name} {text:?} is not a number")))
            };
            let pose = Pose {
                position: Vec2::new(number("x_m", x)?, number("y_m", y)?),
                heading: number("heading_deg", heading)?.to_radians(),
            };
            if trajectory.samples.last().is_some_and(|s| s.t_us > t_us) {
                return Err(row(format!("t_s {t} is before the row above")));
            }
            trajectory.record(t_us, pose);
        }
        Ok(trajectory)
    }

    /// The whole trajectory as CSV, header first.
    pub fn write_csv(&self, out: &mut impl Write) -> io::Result<()> {
        writeln!(out, "{CSV_HEADER}")?;
        for s in &self.samples {
            writeln!(out, "{}", Trajectory::csv_row(s))?;
        }
        Ok(())
    }

    /// The arena with the path: floor patches in their grey, walls black, obstacles dark grey,
    /// the path blue, the robot's body at the end with a tick for its heading. World y points up.
    pub fn svg(&self, arena: &Arena) -> String {
        let mut points: Vec<Vec2> = arena.segments.iter().flat_map(|s| [s.a, s.b]).collect();
        for c in &arena.circles {
            points.push(c.centre.plus(Vec2::new(c.radius, c.radius)));
            points.push(c.centre.minus(Vec2::new(c.radius, c.radius)));
        }
        for mover in &arena.movers {
            points.extend(&mover.route);
        }
        for patch in &arena.floor {
            match &patch.shape {
                FloorShape::Polygon(p) => points.extend(p),
                FloorShape::Line { segments, .. } => {
                    points.extend(segments.iter().flat_map(|s| [s.a, s.b]))
                }
            }
        }
        points.extend(self.samples.iter().map(|s| s.pose.position));
        points.push(arena.start.position);
        let margin = 0.1;
        let min_x = points.iter().map(|p| p.x).fold(f64::INFINITY, f64::min) - margin;
        let max_x = points.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max) + margin;
        let min_y = points.iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - margin;
        let max_y = points.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max) + margin;
        let (w, h) = (max_x - min_x, max_y - min_y);
        let px = 500.0 / w.max(h);
        let mut s = String::new();
        // Writing into a String cannot fail.
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" viewBox="{min_x:.4} {:.4} {w:.4} {h:.4}">"#,
            w * px,
            h * px,
            -max_y
        );
        let _ = writeln!(
            s,
            r#"<g transform="scale(1,-1)"><rect x="{min_x:.4}" y="{min_y:.4}" width="{w:.4}" height="{h:.4}" fill="rgb(255,255,255)"/>"#
        );
        for patch in &arena.floor {
            let g = patch.grey;
            match &patch.shape {
                FloorShape::Polygon(p) => {
                    let _ = writeln!(
                        s,
                        r#"<polygon points="{}" fill="rgb({g},{g},{g})"/>"#,
                        path(p.iter().copied())
                    );
                }
                FloorShape::Line { segments, width } => {
                    for seg in segments {
                        let _ = writeln!(
                            s,
                            r#"<line x1="{:.4}" y1="{:.4}" x2="{:.4}" y2="{:.4}" stroke="rgb({g},{g},{g})" stroke-width="{width:.4}" stroke-linecap="round"/>"#,
                            seg.a.x, seg.a.y, seg.b.x, seg.b.y
                        );
                    }
                }
            }
        }
        for (k, seg) in arena.segments.iter().enumerate() {
            let colour = if k < arena.wall_segments {
                "black"
            } else {
                "dimgrey"
            };
            let _ = writeln!(
                s,
                r#"<line x1="{:.4}" y1="{:.4}" x2="{:.4}" y2="{:.4}" stroke="{colour}" stroke-width="0.01" stroke-linecap="round"/>"#,
                seg.a.x, seg.a.y, seg.b.x, seg.b.y
            );
        }
        for c in &arena.circles {
            let _ = writeln!(
                s,
                r#"<circle cx="{:.4}" cy="{:.4}" r="{:.4}" fill="dimgrey"/>"#,
                c.centre.x, c.centre.y, c.radius
            );
        }
        // A moving obstacle's loop, dashed (the obstacle is drawn where the run left it).
        for mover in &arena.movers {
            let _ = writeln!(
                s,
                r#"<polygon points="{}" fill="none" stroke="dimgrey" stroke-width="0.003" stroke-dasharray="0.02 0.02"/>"#,
                path(mover.route.iter().copied())
            );
        }
        let _ = writeln!(
            s,
            r#"<polyline points="{}" fill="none" stroke="royalblue" stroke-width="0.005"/>"#,
            path(
                std::iter::once(arena.start.position)
                    .chain(self.samples.iter().map(|s| s.pose.position))
            )
        );
        let end = self.samples.last().map_or(arena.start, |s| s.pose);
        let tip = end
            .position
            .plus(Vec2::from_angle(end.heading).scale(BODY_RADIUS_M));
        let _ = writeln!(
            s,
            r#"<circle cx="{:.4}" cy="{:.4}" r="{BODY_RADIUS_M}" fill="none" stroke="crimson" stroke-width="0.004"/><line x1="{:.4}" y1="{:.4}" x2="{:.4}" y2="{:.4}" stroke="crimson" stroke-width="0.004"/>"#,
            end.position.x, end.position.y, end.position.x, end.position.y, tip.x, tip.y
        );
        s.push_str("</g>\n</svg>\n");
        s
    }
}

fn path(points: impl Iterator<Item = Vec2>) -> String {
    points
        .map(|p| format!("{:.4},{:.4}", p.x, p.y))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, y: f64, deg: f64) -> Pose {
        Pose {
            position: Vec2::new(x, y),
            heading: deg.to_radians(),
        }
    }

    #[test]
    fn a_written_trajectory_reads_back_and_bad_rows_are_named() {
        let mut t = Trajectory::default();
        t.record(0, pose(1.0, 0.5, 0.0));
        t.record(1_230_010, pose(-0.25, 0.125, 90.0));
        let mut csv = Vec::new();
        t.write_csv(&mut csv).unwrap();
        let back = Trajectory::read_csv(std::str::from_utf8(&csv).unwrap()).unwrap();
        assert_eq!(back.samples.len(), 2);
        assert_eq!(back.samples[1].t_us, 1_230_010);
        assert_eq!(back.samples[1].pose.position, Vec2::new(-0.25, 0.125));
        assert!((back.samples[1].pose.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert_eq!(
            Trajectory::read_csv("t,x,y,h\n"),
            Err(CsvError::Header("t,x,y,h".into()))
        );
        let bad = |rows: &str| {
            Trajectory::read_csv(&format!("{CSV_HEADER}\n{rows}"))
                .unwrap_err()
                .to_string()
        };
        assert_eq!(bad("0.5,1,2"), "line 2: 3 fields, expected 4");
        assert_eq!(
            bad("0.1,1,2,3\n-1,1,2,3"),
            "line 3: t_s \"-1\" is not a time in seconds"
        );
        assert_eq!(bad("0.1,1,x,3"), "line 2: y_m \"x\" is not a number");
        assert_eq!(
            bad("0.2,1,2,3\n0.1,1,2,3"),
            "line 3: t_s 0.1 is before the row above"
        );
    }

    #[test]
    fn csv_rows_are_exact_and_headed() {
        let mut t = Trajectory::default();
        t.record(0, pose(0.5, 0.25, 0.0));
        t.record(10_000, pose(0.501, 0.25, 190.0));
        let mut out = Vec::new();
        t.write_csv(&mut out).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "t_s,x_m,y_m,heading_deg\n0.000000,0.500000,0.250000,0.000\n\
             0.010000,0.501000,0.250000,-170.000\n"
        );
    }

    #[test]
    fn the_picture_holds_the_arena_and_the_path() {
        let arena = Arena::parse(
            r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
                 "walls": [[[0, 0], [1, 0], [1, 1]]],
                 "obstacles": [ { "circle": [0.8, 0.8], "radius": 0.05 } ],
                 "floor": [ { "polygon": [[0, 0], [0.5, 0], [0.5, 0.5]], "grey": 40 } ] }"#,
        )
        .unwrap();
        let mut t = Trajectory::default();
        t.record(0, pose(0.5, 0.5, 0.0));
        t.record(1, pose(0.6, 0.5, 0.0));
        let svg = t.svg(&arena);
        assert!(svg.starts_with("<svg "));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert_eq!(
            svg.matches(r#"stroke="black""#).count(),
            2,
            "two wall segments"
        );
        assert!(svg.contains(r#"fill="rgb(40,40,40)""#));
        assert!(svg.contains("0.5000,0.5000 0.5000,0.5000 0.6000,0.5000"));
        // The view: the arena from (0, 0) to (1, 1) plus 0.1 m around; y flipped.
        assert!(
            svg.contains(r#"viewBox="-0.1000 -1.1000 1.2000 1.2000""#),
            "{svg}"
        );
    }
}
