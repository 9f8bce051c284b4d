//! The closed loop without firmware, driven by a shell behaviour: publish requests, motor
//! commands and the dead-man, LED commands, and the figures a run reports.

use std::process::Command;
use std::time::Duration;

use amiro_world::controller::Controller;
use amiro_world::{kinematic, Arena, World};

/// For the first second: asks for the ring every 100 ms (low priority, `31F#01640000`), drives
/// at 0.1 m/s (`110#A086010000000000`, high priority) and shows on led-1 (`111#RRGGBB`) how many
/// ring frames (`71F#…`) it has seen. Then it stops sending motor commands.
const BEHAVIOUR: &str = r#"
ticks=0; ring=0
while IFS= read -r line; do
  case "$line" in
    *" 71F#"*) ring=$((ring+1)) ;;
    *" tick")
      ticks=$((ticks+1))
      if [ "$ticks" -eq 1 ]; then echo '31F#01640000'; fi
      if [ "$ticks" -le 100 ]; then echo '110#A086010000000000'; printf '111#%02X0000\n' "$ring"; fi
      echo ok ;;
  esac
done
"#;

fn corridor() -> Arena {
    Arena::parse(
        r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 0 },
             "walls": [[[-1, 0.3], [3, 0.3]], [[-1, -0.3], [3, -0.3]]],
             "floor": [ { "polygon": [[0.1, -0.3], [0.12, -0.3], [0.12, 0.3], [0.1, 0.3]], "grey": 0 } ] }"#,
    )
    .unwrap()
}

#[test]
fn a_shell_behaviour_drives_until_the_dead_man_stops_it() {
    let mut world = World::new(corridor());
    let mut command = Command::new("sh");
    command.arg("-c").arg(BEHAVIOUR);
    let mut c = Controller::spawn_command("behaviour", command, Duration::from_secs(10)).unwrap();
    let outcome = kinematic::run(&mut world, &mut c, 3_000_000, 10_000).unwrap();
    c.finish();
    assert_eq!(outcome.ticks, 300);
    // Commands at the ticks 10 ms … 1000 ms; the last at 1.0 s holds until the dead-man (older
    // than 0.5 s) at 1.51 s: 1.5 s at 0.1 m/s.
    let s = outcome.summary;
    assert!((s.travelled_m - 0.150).abs() < 1e-9, "{s}");
    assert_eq!(s.contacts, 0);
    assert_eq!(
        s.to_string(),
        "world: travelled 0.150 m, contacts 0, pose 0.150 0.000 0.0"
    );
    // The ring published at 0.11 s, 0.21 s, … (100 ms after the request at the first tick);
    // the behaviour's last LED, at 1.0 s, counted nine samples of eight frames.
    assert_eq!(outcome.leds[0], [72, 0, 0]);
    // The dark stripe at x = 0.10–0.12 m is under the front pair (40 mm ahead; a spot is dark
    // when three of its five points are) while the centre goes from 0.06 to 0.08 m, and under the
    // wheel pair from 0.10 to 0.12 m: 2 × 20 mm at 1 mm a tick.
    assert!(
        (38..=42).contains(&outcome.ticks_over_dark),
        "{}",
        outcome.ticks_over_dark
    );
    assert_eq!(outcome.trajectory.samples.len(), 301);
    assert_eq!(outcome.ignored_frames, 0);
}
