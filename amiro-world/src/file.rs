//! The world file: JSON in metres and degrees, read with serde into raw types and then checked
//! into an [`Arena`], so a malformed world is a [`WorldError`] that names the field
//! (`floor[2].grey: 300 is above 255`), never a panic or a made-up number.
//!
//! ```json
//! {
//!   "seed": 7,
//!   "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
//!   "walls": [ [[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]] ],
//!   "obstacles": [ { "circle": [1.0, 1.2], "radius": 0.08 },
//!                  { "polygon": [[1.4, 0.3], [1.6, 0.3], [1.6, 0.5]], "reflectance": 0.5 } ],
//!   "floor": [ { "polygon": [[0, 0], [1, 0], [1, 1]], "grey": 128 },
//!              { "line": [[0.3, 0.3], [1.7, 0.3], [1.7, 1.7]], "width": 0.03, "grey": 0, "closed": true } ],
//!   "lab": { "north_deg": 90, "field_nt": 49000, "inclination_deg": 67 }
//! }
//! ```
//!
//! A wall is a polyline (`[[x, y], …]`) or `{ "points": [[x, y], …], "reflectance": r }`. Floor
//! patches are drawn in order over a white floor (grey 255): the last one that covers a point
//! decides its grey. Every field but `robot` is optional.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::geometry::{Circle, Segment, Vec2};

/// A world file that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file could not be read.
    #[error("reading the world {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// Not JSON, or not the world's shape (serde says where: line, column and the field).
    #[error("world file: {0}")]
    Json(serde_json::Error),
    /// A field with a value the world cannot use.
    #[error("{field}: {problem}")]
    Field {
        /// Where, as a path into the file: `floor[2].grey`.
        field: String,
        /// What is wrong with it.
        problem: Problem,
    },
}

/// What is wrong with a field.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// A list with fewer points than the shape needs.
    TooFewPoints {
        /// Points given.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// A number above its largest allowed value.
    Above {
        /// The value.
        value: f64,
        /// The limit.
        max: f64,
    },
    /// A number below its smallest allowed value.
    Below {
        /// The value.
        value: f64,
        /// The limit.
        min: f64,
    },
    /// The robot's body overlaps a wall or an obstacle where it starts.
    StartsInside {
        /// The wall or obstacle, as a path into the file.
        what: String,
        /// Its distance from the robot's centre, m.
        distance_m: f64,
    },
    /// A floor patch that is neither a `polygon` nor a `line`, or both.
    FloorShape,
    /// An obstacle that is neither a `polygon` nor a `circle`, or both.
    ObstacleShape,
    /// A wall that is neither a list of points nor `{ "points", "reflectance" }`.
    WallShape,
    /// A `path` on something other than a round obstacle.
    OnlyCirclesMove,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::TooFewPoints { found, needed } => {
                write!(f, "{found} points, at least {needed} needed")
            }
            Problem::Above { value, max } => write!(f, "{value} is above {max}"),
            Problem::Below { value, min } => write!(f, "{value} is below {min}"),
            Problem::StartsInside { what, distance_m } => write!(
                f,
                "the robot starts {distance_m:.3} m from {what}, inside its body (radius {:.3} m)",
                BODY_RADIUS_M
            ),
            Problem::FloorShape => write!(f, "needs exactly one of `polygon` or `line`"),
            Problem::ObstacleShape => write!(f, "needs exactly one of `polygon` or `circle`"),
            Problem::OnlyCirclesMove => write!(f, "only a round obstacle (`circle`) moves"),
            Problem::WallShape => write!(
                f,
                "a wall is a list of [x, y] points or {{ \"points\": [...], \"reflectance\": r }}"
            ),
        }
    }
}

fn field(field: impl Into<String>, problem: Problem) -> WorldError {
    WorldError::Field {
        field: field.into(),
        problem,
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorld {
    #[serde(default)]
    seed: u64,
    robot: RawPose,
    /// Read one by one, so a malformed wall is named by its index.
    #[serde(default)]
    walls: Vec<serde_json::Value>,
    #[serde(default)]
    obstacles: Vec<RawObstacle>,
    #[serde(default)]
    floor: Vec<RawFloor>,
    #[serde(default)]
    lab: Option<RawLab>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPose {
    x: f64,
    y: f64,
    heading_deg: f64,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawWall {
    Points(Vec<[f64; 2]>),
    Material(RawMaterialWall),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterialWall {
    points: Vec<[f64; 2]>,
    #[serde(default)]
    reflectance: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObstacle {
    #[serde(default)]
    polygon: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    circle: Option<[f64; 2]>,
    #[serde(default)]
    radius: Option<f64>,
    #[serde(default)]
    reflectance: Option<f64>,
    #[serde(default)]
    path: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    speed: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFloor {
    #[serde(default)]
    polygon: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    line: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    width: Option<f64>,
    #[serde(default)]
    closed: bool,
    grey: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLab {
    #[serde(default)]
    north_deg: Option<f64>,
    #[serde(default)]
    field_nt: Option<f64>,
    #[serde(default)]
    inclination_deg: Option<f64>,
}

/// The body's radius: the AMiRo is 100 mm across (thesis, chapter 2). The robot must start
/// this far clear of every wall and obstacle.
pub const BODY_RADIUS_M: f64 = 0.050;

/// Where the robot starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: Vec2,
    /// Heading, radians counter-clockwise from +x.
    pub heading: f64,
}

/// The shape of a floor patch.
#[derive(Debug, Clone, PartialEq)]
pub enum FloorShape {
    /// A filled polygon.
    Polygon(Vec<Vec2>),
    /// A painted line: the points within `width / 2` of the polyline.
    Line {
        /// The polyline, its last point joined to the first if the line is `closed`.
        segments: Vec<Segment>,
        /// Width, m.
        width: f64,
    },
}

/// A floor patch with its grey level (0 black … 255 white).
#[derive(Debug, Clone, PartialEq)]
pub struct FloorPatch {
    /// Where.
    pub shape: FloorShape,
    /// Grey level.
    pub grey: u8,
}

/// The lab's magnetic field: where magnetic north lies in the world and how strong and steep
/// the field is. The default is Bielefeld's (amiro-sensors' simulated BNO055 uses the same).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabField {
    /// Direction of magnetic north in the world frame, degrees counter-clockwise from +x.
    pub north_deg: f64,
    /// Total intensity, nT.
    pub total_nt: f64,
    /// Inclination, degrees below the horizontal.
    pub inclination_deg: f64,
}

impl LabField {
    /// Bielefeld (52.0° N, 8.5° E): 49 µT at 67° inclination; north along +y.
    pub const BIELEFELD: LabField = LabField {
        north_deg: 90.0,
        total_nt: 49_000.0,
        inclination_deg: 67.0,
    };
}

/// A round obstacle that moves: from its start round the closed loop start → `waypoints` → start,
/// at a constant speed, for ever.
#[derive(Debug, Clone, PartialEq)]
pub struct Mover {
    /// Which of [`Arena::circles`] moves.
    pub circle: usize,
    /// The loop: the start first, then the waypoints.
    pub route: Vec<Vec2>,
    /// Speed along the loop, m/s.
    pub speed: f64,
}

impl Mover {
    /// Where it is `t_s` seconds after the start.
    pub fn position_at(&self, t_s: f64) -> Option<Vec2> {
        let first = *self.route.first()?;
        let legs = || {
            self.route
                .iter()
                .zip(self.route.iter().skip(1).chain(std::iter::once(&first)))
        };
        let length: f64 = legs().map(|(a, b)| b.minus(*a).length()).sum();
        if length <= 0.0 {
            return Some(first);
        }
        let mut s = (self.speed * t_s).rem_euclid(length);
        for (a, b) in legs() {
            let leg = b.minus(*a).length();
            if s <= leg && leg > 0.0 {
                return Some(a.plus(b.minus(*a).scale(s / leg)));
            }
            s -= leg;
        }
        Some(first)
    }
}

/// A checked world.
#[derive(Debug, Clone, PartialEq)]
pub struct Arena {
    /// The noise seed.
    pub seed: u64,
    /// The robot's start.
    pub start: Pose,
    /// Walls and the polygon obstacles' edges.
    pub segments: Vec<Segment>,
    /// Round obstacles, where they are now.
    pub circles: Vec<Circle>,
    /// The round obstacles that move.
    pub movers: Vec<Mover>,
    /// Floor patches, in drawing order.
    pub floor: Vec<FloorPatch>,
    /// The magnetic field.
    pub lab: LabField,
    /// How many of `segments` are walls (the rest are obstacle edges), for the picture.
    pub wall_segments: usize,
}

/// Reflectance accepted: a matt black surface reflects almost nothing, a mirror-like one up to
/// a few times the reference grey card.
const MAX_REFLECTANCE: f64 = 10.0;
/// The fastest a moving obstacle may go, m/s (ten times the robot's top speed).
const MAX_SPEED_M_S: f64 = 5.0;

impl Arena {
    /// Reads and checks a world file.
    pub fn load(path: &Path) -> Result<Arena, WorldError> {
        let text = std::fs::read_to_string(path).map_err(|error| WorldError::Read {
            path: path.to_path_buf(),
            error,
        })?;
        Arena::parse(&text)
    }

    /// Checks a world given as JSON text.
    pub fn parse(text: &str) -> Result<Arena, WorldError> {
        let raw: RawWorld = serde_json::from_str(text).map_err(WorldError::Json)?;
        let start = Pose {
            position: Vec2::new(raw.robot.x, raw.robot.y),
            heading: raw.robot.heading_deg.to_radians(),
        };
        let mut segments = Vec::new();
        for (i, wall) in raw.walls.into_iter().enumerate() {
            let wall: RawWall = serde_json::from_value(wall)
                .map_err(|_| field(format!("walls[{i}]"), Problem::WallShape))?;
            let (points, reflectance, name) = match wall {
                RawWall::Points(p) => (p, None, format!("walls[{i}]")),
                RawWall::Material(m) => (m.points, m.reflectance, format!("walls[{i}].points")),
            };
            let reflectance = check_reflectance(&format!("walls[{i}].reflectance"), reflectance)?;
            let points = check_points(&name, &points, 2)?;
            segments.extend(polyline(&points, false, reflectance));
        }
        let wall_segments = segments.len();
        let mut circles = Vec::new();
        let mut movers = Vec::new();
        for (i, obstacle) in raw.obstacles.iter().enumerate() {
            let name = format!("obstacles[{i}]");
            let reflectance =
                check_reflectance(&format!("{name}.reflectance"), obstacle.reflectance)?;
            match (&obstacle.polygon, obstacle.circle) {
                (Some(polygon), None) => {
                    if obstacle.path.is_some() || obstacle.speed.is_some() {
                        return Err(field(format!("{name}.path"), Problem::OnlyCirclesMove));
                    }
                    let points = check_points(&format!("{name}.polygon"), polygon, 3)?;
                    segments.extend(polyline(&points, true, reflectance));
                }
                (None, Some([x, y])) => {
                    let radius = obstacle.radius.unwrap_or(0.0);
                    at_least(&format!("{name}.radius"), radius, 0.001)?;
                    let centre = Vec2::new(x, y);
                    if let Some(path) = &obstacle.path {
                        let waypoints = check_points(&format!("{name}.path"), path, 1)?;
                        let speed = obstacle.speed.unwrap_or(0.0);
                        at_least(&format!("{name}.speed"), speed, 0.0)?;
                        at_most(&format!("{name}.speed"), speed, MAX_SPEED_M_S)?;
                        movers.push(Mover {
                            circle: circles.len(),
                            route: std::iter::once(centre).chain(waypoints).collect(),
                            speed,
                        });
                    } else if obstacle.speed.is_some() {
                        return Err(field(
                            format!("{name}.path"),
                            Problem::TooFewPoints {
                                found: 0,
                                needed: 1,
                            },
                        ));
                    }
                    circles.push(Circle {
                        centre,
                        radius,
                        reflectance,
                    });
                }
                _ => return Err(field(name, Problem::ObstacleShape)),
            }
        }
        let mut floor = Vec::new();
        for (i, patch) in raw.floor.iter().enumerate() {
            let name = format!("floor[{i}]");
            at_least(&format!("{name}.grey"), patch.grey, 0.0)?;
            at_most(&format!("{name}.grey"), patch.grey, 255.0)?;
            let shape = match (&patch.polygon, &patch.line) {
                (Some(polygon), None) => {
                    FloorShape::Polygon(check_points(&format!("{name}.polygon"), polygon, 3)?)
                }
                (None, Some(line)) => {
                    let points = check_points(&format!("{name}.line"), line, 2)?;
                    let width = patch.width.unwrap_or(0.0);
                    at_least(&format!("{name}.width"), width, 0.001)?;
                    FloorShape::Line {
                        segments: polyline(&points, patch.closed, 1.0),
                        width,
                    }
                }
                _ => return Err(field(name, Problem::FloorShape)),
            };
            floor.push(FloorPatch {
                shape,
                grey: patch.grey.round() as u8,
            });
        }
        let lab = match raw.lab {
            None => LabField::BIELEFELD,
            Some(lab) => {
                let total_nt = lab.field_nt.unwrap_or(LabField::BIELEFELD.total_nt);
                at_least("lab.field_nt", total_nt, 0.0)?;
                at_most("lab.field_nt", total_nt, 1_000_000.0)?;
                let inclination_deg = lab
                    .inclination_deg
                    .unwrap_or(LabField::BIELEFELD.inclination_deg);
                at_least("lab.inclination_deg", inclination_deg, -90.0)?;
                at_most("lab.inclination_deg", inclination_deg, 90.0)?;
                LabField {
                    north_deg: lab.north_deg.unwrap_or(LabField::BIELEFELD.north_deg),
                    total_nt,
                    inclination_deg,
                }
            }
        };
        let arena = Arena {
            seed: raw.seed,
            start,
            segments,
            circles,
            movers,
            floor,
            lab,
            wall_segments,
        };
        arena.check_start()?;
        Ok(arena)
    }

    /// The robot must start clear of every wall and obstacle.
    fn check_start(&self) -> Result<(), WorldError> {
        let p = self.start.position;
        let r = BODY_RADIUS_M;
        for (k, s) in self.segments.iter().enumerate() {
            let d = s.distance_to(p);
            if d < r {
                let what = if k < self.wall_segments {
                    "a wall".to_string()
                } else {
                    "a polygon obstacle".to_string()
                };
                return Err(field(
                    "robot",
                    Problem::StartsInside {
                        what,
                        distance_m: d,
                    },
                ));
            }
        }
        for (k, c) in self.circles.iter().enumerate() {
            let d = c.distance_to(p);
            if d < r {
                return Err(field(
                    "robot",
                    Problem::StartsInside {
                        what: format!("round obstacle {k}"),
                        distance_m: d,
                    },
                ));
            }
        }
        Ok(())
    }

    /// Puts the moving obstacles where they are `t_s` seconds after the start.
    pub fn move_obstacles(&mut self, t_s: f64) {
        for mover in &self.movers {
            if let (Some(p), Some(c)) = (mover.position_at(t_s), self.circles.get_mut(mover.circle))
            {
                c.centre = p;
            }
        }
    }

    /// The grey level under `p`: the last patch that covers it, or white.
    pub fn grey_at(&self, p: Vec2) -> u8 {
        self.floor
            .iter()
            .rev()
            .find(|patch| match &patch.shape {
                FloorShape::Polygon(points) => crate::geometry::inside_polygon(points, p),
                FloorShape::Line { segments, width } => {
                    segments.iter().any(|s| s.distance_to(p) <= width / 2.0)
                }
            })
            .map_or(255, |patch| patch.grey)
    }
}

fn check_points(name: &str, points: &[[f64; 2]], needed: usize) -> Result<Vec<Vec2>, WorldError> {
    if points.len() < needed {
        return Err(field(
            name,
            Problem::TooFewPoints {
                found: points.len(),
                needed,
            },
        ));
    }
    for (k, [x, y]) in points.iter().enumerate() {
        for (axis, v) in [("x", x), ("y", y)] {
            // A kilometre-wide arena is a typo, and would make the picture useless.
            at_most(&format!("{name}[{k}].{axis}"), v.abs(), 1000.0)?;
        }
    }
    Ok(points.iter().map(|&[x, y]| Vec2::new(x, y)).collect())
}

fn check_reflectance(name: &str, value: Option<f64>) -> Result<f64, WorldError> {
    let r = value.unwrap_or(1.0);
    at_least(name, r, 0.0)?;
    at_most(name, r, MAX_REFLECTANCE)?;
    Ok(r)
}

fn at_least(name: &str, value: f64, min: f64) -> Result<(), WorldError> {
    if value < min {
        return Err(field(name, Problem::Below { value, min }));
    }
    Ok(())
}

fn at_most(name: &str, value: f64, max: f64) -> Result<(), WorldError> {
    if value > max {
        return Err(field(name, Problem::Above { value, max }));
    }
    Ok(())
}

fn polyline(points: &[Vec2], closed: bool, reflectance: f64) -> Vec<Segment> {
    let mut segments: Vec<Segment> = points
        .windows(2)
        .map(|w| Segment {
            a: w[0],
            b: w[1],
            reflectance,
        })
        .collect();
    if let (true, Some(&first), Some(&last)) = (closed, points.first(), points.last()) {
        if first != last {
            segments.push(Segment {
                a: last,
                b: first,
                reflectance,
            });
        }
    }
    segments
}
