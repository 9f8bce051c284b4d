//! The world for Foxglove's 3D panel: the robot's pose over time (`foxglove.PoseInFrame` on
//! `/world/pose`) and the arena once (`foxglove.SceneUpdate` on `/world/arena`: walls and polygon
//! obstacles as line segments, round obstacles as cylinders, the floor's patches as lines on
//! the ground), as JSON messages. Foxglove recognises the schemas by these names; the JSON
//! schemas describe the fields sent. The MCAP file they go into is `amiro record`'s
//! (`operator::record`, `amiro record --world --trajectory`): one writer for the format.

use serde_json::{json, Value};

use crate::file::{Arena, FloorShape, Pose};

/// The frame everything is drawn in.
pub const FRAME: &str = "world";
/// The pose channel.
pub const POSE_TOPIC: &str = "/world/pose";
/// The arena channel.
pub const ARENA_TOPIC: &str = "/world/arena";
/// The pose messages' schema name, as Foxglove knows it.
pub const POSE_SCHEMA: &str = "foxglove.PoseInFrame";
/// The arena messages' schema name, as Foxglove knows it.
pub const SCENE_SCHEMA: &str = "foxglove.SceneUpdate";

fn time(t_us: u64) -> Value {
    json!({ "sec": t_us / 1_000_000, "nsec": (t_us % 1_000_000) * 1000 })
}

fn point(x: f64, y: f64, z: f64) -> Value {
    json!({ "x": x, "y": y, "z": z })
}

fn identity() -> Value {
    json!({ "position": point(0.0, 0.0, 0.0), "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 } })
}

/// A `foxglove.PoseInFrame` for the robot at `t_us`: position on the floor, heading as a
/// rotation about z.
pub fn pose_in_frame(t_us: u64, pose: &Pose) -> Value {
    let half = pose.heading / 2.0;
    json!({
        "timestamp": time(t_us),
        "frame_id": FRAME,
        "pose": {
            "position": point(pose.position.x, pose.position.y, 0.0),
            "orientation": { "x": 0.0, "y": 0.0, "z": half.sin(), "w": half.cos() },
        },
    })
}

/// A `foxglove.SceneUpdate` with the arena as one entity.
pub fn scene_update(arena: &Arena) -> Value {
    let colour = |r: f64, g: f64, b: f64| json!({ "r": r, "g": g, "b": b, "a": 1.0 });
    let segment_points = |range: std::ops::Range<usize>, z: f64| -> Vec<Value> {
        arena.segments[range]
            .iter()
            .flat_map(|s| [point(s.a.x, s.a.y, z), point(s.b.x, s.b.y, z)])
            .collect()
    };
    let line_list = |points: Vec<Value>, thickness: f64, colour: Value| {
        json!({
            "type": 2, "pose": identity(), "thickness": thickness, "scale_invariant": false,
            "points": points, "color": colour, "colors": [], "indices": [],
        })
    };
    let mut lines = vec![
        line_list(
            segment_points(0..arena.wall_segments, 0.05),
            0.01,
            colour(0.1, 0.1, 0.1),
        ),
        line_list(
            segment_points(arena.wall_segments..arena.segments.len(), 0.05),
            0.01,
            colour(0.4, 0.4, 0.4),
        ),
    ];
    for patch in &arena.floor {
        let g = f64::from(patch.grey) / 255.0;
        let (points, thickness) = match &patch.shape {
            FloorShape::Polygon(p) => (
                p.iter()
                    .zip(p.iter().cycle().skip(1))
                    .flat_map(|(a, b)| [point(a.x, a.y, 0.001), point(b.x, b.y, 0.001)])
                    .collect(),
                0.005,
            ),
            FloorShape::Line { segments, width } => (
                segments
                    .iter()
                    .flat_map(|s| [point(s.a.x, s.a.y, 0.001), point(s.b.x, s.b.y, 0.001)])
                    .collect(),
                *width,
            ),
        };
        lines.push(line_list(points, thickness, colour(g, g, g)));
    }
    let cylinders: Vec<Value> = arena
        .circles
        .iter()
        .map(|c| {
            json!({
                "pose": { "position": point(c.centre.x, c.centre.y, 0.05),
                          "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 } },
                "size": point(2.0 * c.radius, 2.0 * c.radius, 0.1),
                "bottom_scale": 1.0, "top_scale": 1.0, "color": colour(0.4, 0.4, 0.4),
            })
        })
        .collect();
    json!({
        "deletions": [],
        "entities": [{
            "timestamp": time(0), "frame_id": FRAME, "id": "arena",
            "lifetime": { "sec": 0, "nsec": 0 }, "frame_locked": false, "metadata": [],
            "arrows": [], "cubes": [], "spheres": [], "cylinders": cylinders, "lines": lines,
            "triangles": [], "texts": [], "models": [],
        }],
    })
}

fn object(properties: Value) -> Value {
    json!({ "type": "object", "properties": properties })
}

/// The JSON schema of `foxglove.PoseInFrame` (the fields sent).
pub fn pose_schema() -> Value {
    let number = json!({ "type": "number" });
    let vector = object(json!({ "x": number, "y": number, "z": number }));
    object(json!({
        "timestamp": object(json!({ "sec": { "type": "integer" }, "nsec": { "type": "integer" } })),
        "frame_id": { "type": "string" },
        "pose": object(json!({
            "position": vector,
            "orientation": object(json!({ "x": number, "y": number, "z": number, "w": number })),
        })),
    }))
}

/// The JSON schema of `foxglove.SceneUpdate` (the fields sent; primitives as objects).
pub fn scene_schema() -> Value {
    let list = json!({ "type": "array", "items": { "type": "object" } });
    object(json!({
        "deletions": list,
        "entities": { "type": "array", "items": object(json!({
            "timestamp": { "type": "object" }, "frame_id": { "type": "string" }, "id": { "type": "string" },
            "lifetime": { "type": "object" }, "frame_locked": { "type": "boolean" }, "metadata": list,
            "arrows": list, "cubes": list, "spheres": list, "cylinders": list, "lines": list,
            "triangles": list, "texts": list, "models": list,
        })) },
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Vec2;

    #[test]
    fn a_pose_turned_a_quarter_is_a_quaternion_about_z() {
        let p = pose_in_frame(
            1_500_000,
            &Pose {
                position: Vec2::new(0.5, 0.25),
                heading: std::f64::consts::FRAC_PI_2,
            },
        );
        assert_eq!(p["timestamp"], json!({ "sec": 1, "nsec": 500_000_000 }));
        assert_eq!(p["frame_id"], "world");
        let q = &p["pose"]["orientation"];
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q["z"].as_f64().unwrap() - h).abs() < 1e-12);
        assert!((q["w"].as_f64().unwrap() - h).abs() < 1e-12);
        assert_eq!(
            p["pose"]["position"],
            json!({ "x": 0.5, "y": 0.25, "z": 0.0 })
        );
    }

    #[test]
    fn the_scene_holds_the_walls_obstacles_and_floor() {
        let arena = Arena::parse(
            r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
                 "walls": [[[0, 0], [1, 0], [1, 1]]],
                 "obstacles": [ { "circle": [0.8, 0.8], "radius": 0.05 },
                                { "polygon": [[0.1, 0.8], [0.2, 0.8], [0.2, 0.9]] } ],
                 "floor": [ { "line": [[0.1, 0.1], [0.9, 0.1]], "width": 0.03, "grey": 0 } ] }"#,
        )
        .unwrap();
        let s = scene_update(&arena);
        let entity = &s["entities"][0];
        let lines = entity["lines"].as_array().unwrap();
        // Walls: two segments, four points; obstacle: three edges, six points; the line: two.
        assert_eq!(lines[0]["points"].as_array().unwrap().len(), 4);
        assert_eq!(lines[1]["points"].as_array().unwrap().len(), 6);
        assert_eq!(lines[2]["points"].as_array().unwrap().len(), 2);
        assert_eq!(lines[2]["thickness"], 0.03);
        assert_eq!(entity["cylinders"][0]["size"]["x"], 0.1);
    }
}
