//! The world file's checks: a world that parses, obstacles that move, and errors that name the
//! field.

use amiro_world::file::{Arena, LabField, WorldError};
use amiro_world::geometry::Vec2;

const BOX: &str = r#""walls": [[[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]]]"#;

fn world(rest: &str) -> Result<Arena, WorldError> {
    Arena::parse(&format!(
        r#"{{ "robot": {{ "x": 1, "y": 1, "heading_deg": 90 }}, {BOX}{rest} }}"#
    ))
}

#[test]
fn a_box_with_a_grey_patch_and_a_line() {
    let a = world(
        r#", "floor": [ { "polygon": [[0, 0], [1, 0], [1, 1], [0, 1]], "grey": 100 },
                       { "line": [[0.5, 0.2], [0.5, 1.8]], "width": 0.04, "grey": 0 } ],
            "obstacles": [ { "circle": [1.5, 1.5], "radius": 0.1, "reflectance": 0.5 } ],
            "seed": 42"#,
    )
    .unwrap();
    assert_eq!(a.segments.len(), 4);
    assert_eq!(a.wall_segments, 4);
    assert_eq!(a.circles.len(), 1);
    assert_eq!(a.seed, 42);
    assert!((a.start.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!(a.grey_at(Vec2::new(0.8, 0.5)), 100);
    // The line is drawn after the patch: it wins where both cover.
    assert_eq!(a.grey_at(Vec2::new(0.51, 0.5)), 0);
    assert_eq!(a.grey_at(Vec2::new(0.53, 1.5)), 255);
    assert_eq!(a.grey_at(Vec2::new(1.5, 0.5)), 255);
    assert_eq!(a.lab, LabField::BIELEFELD);
}

#[test]
fn an_obstacle_moves_round_its_loop() {
    let mut a = world(
        r#", "obstacles": [ { "circle": [0.5, 0.5], "radius": 0.05, "path": [[1.5, 0.5]], "speed": 0.5 } ]"#,
    )
    .unwrap();
    // Out along 1 m and back: a 2 m loop at 0.5 m/s, 4 s a lap.
    for (t, x) in [
        (0.0, 0.5),
        (1.0, 1.0),
        (2.0, 1.5),
        (3.0, 1.0),
        (4.0, 0.5),
        (5.0, 1.0),
    ] {
        a.move_obstacles(t);
        assert!((a.circles[0].centre.x - x).abs() < 1e-12, "t = {t}");
        assert!((a.circles[0].centre.y - 0.5).abs() < 1e-12);
    }
    let e = world(
        r#", "obstacles": [ { "polygon": [[0.1,0.1],[0.2,0.1],[0.2,0.2]], "path": [[1, 1]] } ]"#,
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "obstacles[0].path: only a round obstacle (`circle`) moves"
    );
    let e = world(r#", "obstacles": [ { "circle": [0.5, 0.5], "radius": 0.05, "path": [[1, 1]], "speed": 9 } ]"#)
        .unwrap_err();
    assert_eq!(e.to_string(), "obstacles[0].speed: 9 is above 5");
}

#[test]
fn errors_name_the_field() {
    let e = world(
        r#", "floor": [ { "polygon": [[0,0],[1,0],[1,1]], "grey": 0 },
                       { "polygon": [[0,0],[1,0],[1,1]], "grey": 10 },
                       { "polygon": [[0,0],[1,0],[1,1]], "grey": 300 } ]"#,
    )
    .unwrap_err();
    assert_eq!(e.to_string(), "floor[2].grey: 300 is above 255");
    let e = world(r#", "floor": [ { "polygon": [[0,0],[1,0]], "grey": 0 } ]"#).unwrap_err();
    assert_eq!(
        e.to_string(),
        "floor[0].polygon: 2 points, at least 3 needed"
    );
    let e = world(r#", "obstacles": [ { "circle": [1.5, 1.5] } ]"#).unwrap_err();
    assert_eq!(e.to_string(), "obstacles[0].radius: 0 is below 0.001");
    let e = world(r#", "obstacles": [ { "radius": 0.1 } ]"#).unwrap_err();
    assert_eq!(
        e.to_string(),
        "obstacles[0]: needs exactly one of `polygon` or `circle`"
    );
    let e = world(r#", "lab": { "inclination_deg": 91 }"#).unwrap_err();
    assert_eq!(e.to_string(), "lab.inclination_deg: 91 is above 90");
    let e = Arena::parse(
        r#"{ "robot": { "x": 1, "y": 1, "heading_deg": 0 },
             "walls": [ [[0, 0], [2, 0]], { "points": [[0, 2], [2, 2]], "reflectance": 0.5 }, 5 ] }"#,
    )
    .unwrap_err();
    assert!(
        e.to_string().starts_with("walls[2]: a wall is a list"),
        "{e}"
    );
    let e = Arena::parse(
        r#"{ "robot": { "x": 1, "y": 1, "heading_deg": 0 },
             "walls": [ { "points": [[0, 2], [2, 2]], "reflectanc": 0.5 } ] }"#,
    )
    .unwrap_err();
    assert!(e.to_string().starts_with("walls[0]:"), "{e}");
    let e = Arena::parse(
        r#"{ "robot": { "x": 1, "y": 1, "heading_deg": 0 },
             "walls": [ { "points": [[0, 2]], "reflectance": 0.5 } ] }"#,
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "walls[0].points: 1 points, at least 2 needed"
    );
}

#[test]
fn a_robot_in_a_wall_and_broken_json_are_refused() {
    let e = Arena::parse(
        r#"{ "robot": { "x": 0.03, "y": 1, "heading_deg": 0 }, "walls": [[[0, 0], [0, 2]]] }"#,
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("robot: the robot starts 0.030 m from a wall"),
        "{e}"
    );
    let e = Arena::parse(r#"{ "robot": { "x": 1, "y": 1 } }"#).unwrap_err();
    assert!(e.to_string().contains("heading_deg"), "{e}");
    let e = Arena::parse(r#"{ "robot": { "x": 1, "y": 1, "heading_deg": 0 }, "wals": [] }"#)
        .unwrap_err();
    assert!(e.to_string().contains("wals"), "{e}");
}
