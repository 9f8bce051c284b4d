"""The example behaviours (examples/*.py, python-can message types) close the loop against amiro-world.

Lock-step: `world-loop` (amiro-world's kinematic loop: the world, and a thin stand-in for the boards that answers
publish requests and motor commands through amiro-can) runs each example unchanged through the controller
protocol on its stdin/stdout. Live: the same behaviour objects on a python-can bus (the `virtual` interface here;
`slcan` on `cargo xtask robot --slcan`'s port is the same code path), fed ring and floor frames as a robot sends
them. The same examples against the emulated firmware are robot scenarios (world-avoidance, world-line: docs/world.md).

Run by `cargo xtask test` (xtask/src/interop.rs: AMIRO_WORLD_LOOP is the world-loop binary); by hand:
    cargo build -p amiro-world --bin world-loop
    AMIRO_WORLD_LOOP=target/debug/world-loop python -m pytest tools/interop/test_world_examples.py
"""

import csv
import json
import math
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest

ROOT = Path(__file__).resolve().parents[2]
WORLD_LOOP = os.environ.get("AMIRO_WORLD_LOOP")
sys.path.insert(0, str(ROOT / "examples"))

import amiro_behaviour  # noqa: E402
from line_following import LineFollowing  # noqa: E402
from obstacle_avoidance import ObstacleAvoidance  # noqa: E402


def world_loop(tmp_path, world, example, seconds, name):
    if not WORLD_LOOP:
        pytest.skip("AMIRO_WORLD_LOOP names no world-loop binary")
    trajectory = tmp_path / f"{name}.csv"
    out = subprocess.run(
        [WORLD_LOOP, str(ROOT / "robot" / "worlds" / world),
         "--controller", f"{sys.executable} {ROOT / 'examples' / example}",
         "--duration-s", str(seconds), "--trajectory", str(trajectory), "--svg", str(tmp_path / f"{name}.svg")],
        capture_output=True, text=True, timeout=600, check=True,
    ).stdout
    end = [line for line in out.splitlines() if line.startswith("world: travelled")]
    assert len(end) == 1, out
    words = end[0].replace(",", "").split()
    figures = {"travelled": float(words[2]), "contacts": int(words[5])}
    dark = next(line for line in out.splitlines() if "over dark" in line)
    figures["dark_percent"] = float(dark.split(" at ")[1].split(" %")[0])
    figures["leds"] = next(line for line in out.splitlines() if line.startswith("world: leds")).split()[2:]
    figures["trajectory"] = trajectory.read_text()
    return figures


def test_obstacle_avoidance_roams_the_arena_without_touching(tmp_path):
    f = world_loop(tmp_path, "arena.json", "obstacle_avoidance.py", 60, "avoid")
    assert f["contacts"] == 0, f
    assert f["travelled"] >= 3.0, f
    rows = list(csv.DictReader(f["trajectory"].splitlines()))
    assert len(rows) == 6001 and rows[0]["t_s"] == "0.000000" and rows[-1]["t_s"] == "60.000000"


def test_line_following_completes_a_lap_over_the_line(tmp_path):
    f = world_loop(tmp_path, "line-lap.json", "line_following.py", 60, "line")
    assert f["dark_percent"] >= 90.0, f
    # A lap: the angle round the stadium's centre (1.0, 0.75) grows by a full turn.
    turned, previous = 0.0, None
    for row in csv.DictReader(f["trajectory"].splitlines()):
        a = math.atan2(float(row["y_m"]) - 0.75, float(row["x_m"]) - 1.0)
        if previous is not None:
            turned += (a - previous + math.pi) % (2 * math.pi) - math.pi
        previous = a
    assert turned >= 2 * math.pi, f"{turned / (2 * math.pi):.2f} laps"


def test_amiro_record_adds_the_world_for_foxglove(tmp_path):
    """A run's bus log and trajectory through `amiro record --world --trajectory` (the one MCAP writer), read back
    with Foxglove's reader: the bus's channels, the arena once, a pose per trajectory row in time order."""
    from mcap.reader import make_reader
    if not WORLD_LOOP:
        pytest.skip("AMIRO_WORLD_LOOP names no world-loop binary")
    amiro = os.environ.get("AMIRO", "amiro")
    world = ROOT / "robot" / "worlds" / "arena.json"
    log, trajectory, out = tmp_path / "bus.log", tmp_path / "trajectory.csv", tmp_path / "world.mcap"
    subprocess.run(
        [WORLD_LOOP, str(world),
         "--controller", f"{sys.executable} {ROOT / 'examples' / 'obstacle_avoidance.py'}",
         "--duration-s", "1", "--bus-log", str(log), "--trajectory", str(trajectory)],
        capture_output=True, text=True, timeout=600, check=True,
    )
    recorded = subprocess.run(
        [amiro, "record", "--bus", f"file:{log}", "--out", str(out), "--world", str(world),
         "--trajectory", str(trajectory)],
        capture_output=True, text=True, timeout=600,
    )
    assert recorded.returncode == 0, recorded.stderr
    frames = len(log.read_text().splitlines())
    assert f"recorded {frames} frames and 101 poses" in recorded.stderr
    seen, times = {}, []
    with open(out, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            seen.setdefault(channel.topic, (schema.name, []))[1].append(json.loads(message.data))
            times.append(message.log_time)
    assert times == sorted(times), "the poses go in between the frames, in time order"
    assert seen["/world/arena"][0] == "foxglove.SceneUpdate"
    assert len(seen["/world/arena"][1]) == 1
    assert seen["/world/pose"][0] == "foxglove.PoseInFrame"
    poses = seen["/world/pose"][1]
    assert len(poses) == 101 and poses[0]["pose"]["position"] == {"x": 0.3, "y": 0.75, "z": 0.0}
    assert len(seen["/amiro/frames"][1]) == frames
    assert "/amiro/motor/command" in seen and "/amiro/proximity-ring" in seen
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,x_m,y_m,heading_deg\n0.0,1,2\n")
    refused = subprocess.run(
        [amiro, "record", "--bus", f"file:{log}", "--out", str(tmp_path / "x.mcap"), "--trajectory", str(bad)],
        capture_output=True, text=True, timeout=600,
    )
    assert refused.returncode != 0 and "line 2: 3 fields, expected 4" in refused.stderr, refused.stderr


def test_runs_are_deterministic(tmp_path):
    a = world_loop(tmp_path, "arena.json", "obstacle_avoidance.py", 10, "a")
    b = world_loop(tmp_path, "arena.json", "obstacle_avoidance.py", 10, "b")
    assert a["trajectory"] == b["trajectory"]


def ring_frame(sensor, mm):
    return can.Message(arbitration_id=0x71F, data=struct.pack("<BH", sensor, mm), is_extended_id=False)


def test_the_same_behaviour_runs_live_on_a_python_can_bus():
    """run_live, the transport `--slcan` uses, on python-can's virtual bus: publish request first, motor
    commands every 50 ms, the LED towards the obstacle, and a stop when it ends."""
    channel = f"amiro-world-{os.getpid()}"
    with can.Bus(interface="virtual", channel=channel) as robot, \
            can.Bus(interface="virtual", channel=channel) as behaviour_bus:
        worker = threading.Thread(
            target=amiro_behaviour.run_live, args=(ObstacleAvoidance(), behaviour_bus, 0.5))
        worker.start()
        first = robot.recv(timeout=2)
        assert (first.arbitration_id, bytes(first.data)) == (0x31F, bytes([1, 60, 0, 0]))
        # Something 40 mm away, front-left (sensor 3): turn on the spot, led-8 red.
        for sensor in range(8):
            robot.send(ring_frame(sensor, 40 if sensor == 3 else 200))
        heard = []
        deadline = time.monotonic() + 3
        while worker.is_alive() and time.monotonic() < deadline:
            msg = robot.recv(timeout=0.1)
            if msg is not None:
                heard.append(msg)
        worker.join()
        # The stop is sent as the worker ends, possibly after the loop's last look.
        while (msg := robot.recv(timeout=0.2)) is not None:
            heard.append(msg)
    motors = [struct.unpack("<ii", bytes(m.data)) for m in heard if m.arbitration_id == 0x110]
    assert len(motors) >= 5, heard
    assert motors[-1] == (0, 0), "the last command stops the robot"
    assert any(v == 0 and w < 0 for v, w in motors), motors  # left is nearer: turns right on the spot
    leds = {m.arbitration_id: bytes(m.data) for m in heard if 0x311 <= m.arbitration_id <= 0x318}
    assert leds[0x318][0] > 200 and leds[0x318][1:] == b"\0\0", leds


def test_line_following_steers_towards_the_line():
    b = LineFollowing()
    floor = lambda fr, fl: can.Message(arbitration_id=0x704, data=struct.pack("<4H", fr, 37000, 37000, fl),
                                       is_extended_id=False)
    b.on_message(floor(6000, 37000))     # the left sensor is off the line: the line is to the right
    v, w = struct.unpack("<ii", bytes(b.tick(0.0)[0].data))
    assert v > 0 and w < 0
    b.on_message(floor(37000, 37000))    # lost: turn towards where it was seen last (right)
    v, w = struct.unpack("<ii", bytes(b.tick(0.1)[0].data))
    assert v == 0 and w < 0


def test_the_lockstep_transport_speaks_the_controller_protocol():
    """run_lockstep on text streams: frames in, the publish request and motor command at the first tick, `ok`."""
    import io
    stdin = io.StringIO(
        "(0.005000) can0 71F#032800\n"          # sensor 3 (front-left) at 40 mm
        "(0.010000) tick\n"
        "(0.020000) tick\n"
    )
    stdout = io.StringIO()
    amiro_behaviour.run_lockstep(ObstacleAvoidance(), stdin, stdout)
    lines = stdout.getvalue().splitlines()
    first = lines[: lines.index("ok")]
    assert first[0] == "31F#013C0000"
    assert first[1] == "110#00000000807BE1FF", first    # on the spot, −2 rad/s: away from the left
    assert "318#D80000" in first, first                 # led-8 red: 64 + 191 · 160 / 200 = 216
    assert lines[lines.index("ok") + 1:] == ["ok"], "nothing new 10 ms later"
