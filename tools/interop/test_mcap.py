"""The Python `mcap` reader (Foxglove's own library) opens the MCAP files `amiro` writes: channels, JSON schemas,
messages and their log times.

Run by `cargo xtask test` (xtask/src/interop.rs) in a venv with tools/requirements-ci.txt; by hand:
    AMIRO=target/debug/amiro python -m pytest tools/interop/test_mcap.py
"""

import json
import os
import subprocess
from pathlib import Path

import pytest
from mcap.reader import make_reader

AMIRO = os.environ.get("AMIRO", "amiro")

# A publish request, five gyroscope samples (one 100 ms late), the other sensors, a motor and an LED command,
# a diagnostics page and a frame the robot rejects (DLC too short).
LOG = """\
(1700000000.000000) can0 108#01640000
(1700000000.100000) can0 508#FCFF1E00FBFF
(1700000000.200000) can0 508#FDFF1F00FBFF
(1700000000.300000) can0 508#FEFF2000FBFF
(1700000000.500000) can0 508#FFFF2100FBFF
(1700000000.510000) can0 71E#003E4701720C
(1700000000.520000) can0 701#393000FDFFFF0040
(1700000000.530000) can0 71F#037800
(1700000000.540000) can0 010#A0860100B03CFFFF
(1700000000.550000) can0 313#FF8020
(1700000000.560000) can0 71A#00100E0000060903
(1700000000.570000) can0 205#0184
(1700000000.600000) can0 508#00002200FBFF
"""


def ns(stamp):
    secs, micros = stamp.split(".")
    return int(secs) * 1_000_000_000 + int(micros) * 1000


@pytest.fixture(scope="module", params=["record", "decode"])
def recording(request, tmp_path_factory):
    """The log written to MCAP by `amiro record --bus file:` and by `amiro decode --mcap`."""
    base = os.environ.get("AMIRO_INTEROP_DIR")
    work = Path(base) / "mcap" if base else tmp_path_factory.mktemp("mcap")
    work.mkdir(parents=True, exist_ok=True)
    log = work / "run.log"
    log.write_text(LOG)
    out = work / f"{request.param}.mcap"
    if request.param == "record":
        args = ["record", "--bus", f"file:{log}", "--out", str(out)]
    else:
        args = ["decode", "--file", str(log), "--mcap", str(out)]
    result = subprocess.run([AMIRO, *args], capture_output=True, text=True, check=False)
    # `decode` exits 1 because one frame is rejected; the recording is complete all the same.
    assert result.returncode in (0, 1), result.stderr
    assert out.exists(), result.stderr
    return out


def decoded(path):
    """(channel, schema, log time, publish time, message) for every message, in log-time order."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        return [
            (channel.topic, schema, message.log_time, message.publish_time, json.loads(message.data))
            for schema, channel, message in reader.iter_messages(log_time_order=True)
        ]


def test_channels_and_schemas(recording):
    with open(recording, "rb") as stream:
        summary = make_reader(stream).get_summary()
    channels = {channel.topic: channel for channel in summary.channels.values()}
    for topic in [
        "/amiro/frames",
        "/amiro/gyroscope",
        "/amiro/power-status",
        "/amiro/odometry",
        "/amiro/proximity-ring",
        "/amiro/diwheeldrive-diagnostics",
        "/amiro/gyroscope/command",
        "/amiro/motor/command",
        "/amiro/led-3/command",
    ]:
        assert topic in channels, sorted(channels)
        channel = channels[topic]
        assert channel.message_encoding == "json"
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "jsonschema"
        json.loads(schema.data)
    gyroscope = json.loads(summary.schemas[channels["/amiro/gyroscope"].schema_id].data)
    assert gyroscope["required"] == ["priority", "x_dps", "y_dps", "z_dps"]
    assert all(gyroscope["properties"][axis]["type"] == "integer" for axis in ["x_dps", "y_dps", "z_dps"])
    assert channels["/amiro/gyroscope"].metadata["board"] == "DiWheelDrive"
    assert summary.statistics.message_count == len(decoded(recording))


def test_messages_carry_the_values_of_decode_json_at_their_frames_times(recording):
    messages = decoded(recording)
    lines = [line.split() for line in LOG.splitlines()]
    frames = [m for m in messages if m[0] == "/amiro/frames"]
    assert [m[4]["frame"] for m in frames] == [line[2] for line in lines]
    assert [m[2] for m in frames] == [ns(line[0].strip("()")) for line in lines]
    assert all(m[2] == m[3] for m in messages), "publish time = log time"

    # The values are those `amiro decode --json` prints, field for field.
    json_lines = subprocess.run(
        [AMIRO, "decode", "--json"], input=LOG, capture_output=True, text=True, check=False
    ).stdout.splitlines()
    by_frame = {}
    for line in json_lines:
        record = json.loads(line)
        if record.get("ok") and "values" in record:
            by_frame.setdefault(record["frame"], record)
    for channel, _, log_time, _, message in messages:
        if channel == "/amiro/frames" or channel.endswith("/command"):
            continue
        frame = next(m[4]["frame"] for m in frames if m[2] == log_time)
        record = by_frame[frame]
        assert channel == "/amiro/" + record["topic"]
        assert message == {"priority": record["priority"], **record["values"]}

    gyroscope = [(m[2], m[4]) for m in messages if m[0] == "/amiro/gyroscope"]
    assert [t for t, _ in gyroscope] == [ns(s) for s in
        ["1700000000.100000", "1700000000.200000", "1700000000.300000", "1700000000.500000", "1700000000.600000"]]
    assert [v["x_dps"] for _, v in gyroscope] == [-4, -3, -2, -1, 0]
    assert gyroscope[0][1] == {"priority": "high", "x_dps": -4, "y_dps": 30, "z_dps": -5}

    motor = [m[4] for m in messages if m[0] == "/amiro/motor/command"]
    assert motor == [{"priority": "urgent", "action": "motor", "velocity_um_s": 100000, "angular_urad_s": -50000}]
    rejected = [m[4] for m in frames if not m[4]["ok"]]
    assert [r["error"] for r in rejected] == ["dlc-too-short"]
