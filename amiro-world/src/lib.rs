//! A world for the virtual AMiRo: an arena read from a JSON file, the robot's body moving in it
//! on its two wheels, and what its sensors see there — the eight proximity-ring sensors, the
//! four floor sensors and the IMU — with seeded noise, so the same world, seed and wheel inputs
//! give the same readings byte for byte. Plus the run's outputs (trajectory CSV, the end line,
//! an SVG of the arena) and the lock-step [`controller`] protocol for operator-side behaviours.
//!
//! The models, their sources and parameters are in docs/world.md; each module's documentation
//! says the same beside the code.
//!
//! | module | owns |
//! |---|---|
//! | [`file`](mod@file) | the world file's format and its checks ([`Arena`], [`WorldError`]) |
//! | [`geometry`] | points, segments, circles, rays, polygons |
//! | [`motion`] | the pose from the wheels' travel, the body stopped by walls, contacts |
//! | [`ring`], [`floor`], [`imu`] | the sensor models |
//! | [`noise`] | the seeded generator |
//! | [`world`] | the three together: [`World`], [`Readings`], [`Summary`] (the end line) |
//! | [`output`] | trajectory CSV and SVG |
//! | [`foxglove`] | the pose and the arena for Foxglove's 3D panel, in an MCAP file |
//! | [`controller`] | the controller protocol |
//! | [`feed`] | the robot link's world messages: wheel reports in, each board's readings out |
//! | [`kinematic`] | a closed loop without firmware: behaviours against the world alone |

pub mod controller;
pub mod feed;
pub mod file;
pub mod floor;
pub mod foxglove;
pub mod geometry;
pub mod imu;
pub mod kinematic;
pub mod motion;
pub mod noise;
pub mod output;
pub mod ring;
pub mod world;

pub use file::{Arena, Pose, WorldError};
pub use output::Trajectory;
pub use world::{Readings, Summary, World};
