"""Other CAN tools read what `amiro` writes: its DBC file in cantools, its candump logs in python-can and can-utils.

Run by `cargo xtask test` (xtask/src/interop.rs) in a venv with tools/requirements-ci.txt; by hand:
    AMIRO=target/debug/amiro python -m pytest tools/interop
"""

import json
import os
import shutil
import subprocess
from pathlib import Path

import can
import cantools
import pytest

AMIRO = os.environ.get("AMIRO", "amiro")

# Deadline misses urgent 1, high 2, medium 3, low 16383 (page 5 packs four 14-bit counters).
_PACKED = (1 | 2 << 14 | 3 << 28 | 0x3FFF << 42).to_bytes(8, "little")[:7].hex().upper()

# One frame of every kind: every sensor topic's data, every command form, every diagnostics page, both verdict
# pages, the policy and the shutdown command.
FRAMES = [
    "701#393000FDFFFF0040",  # odometry
    "502#A0860100B03CFFFF",  # velocity
    "404#36012701" "0C00D403",  # floor proximity
    "605#08520000",  # magnetometer x, the thesis example's answer
    "706#F8ADFFFF",  # magnetometer y
    "407#10270000",  # magnetometer z
    "508#FCFF1E000500",  # gyroscope
    "609#1A00FEFF0E04",  # accelerometer
    "71E#003E4701720C",  # power status
    "71F#037800",  # proximity ring
    "205#01840302",  # publish magnetometer x every 900 µs (the thesis example)
    "204#02",  # once floor proximity
    "31F#00",  # stop proximity ring
    "010#A0860100B03CFFFF",  # motor
    "113#0A3278",  # led 3
    "21A#0301",  # admission policy accept-and-warn
    "01D#0355AA",  # shutdown, transportation
    "71A#00100E0000060903",  # diagnostics: status
    "71B#0140420FFFFFFF19",  # commands
    "61C#020901000001FFFF",  # rejections
    "71A#0302000100341207",  # admission and receive
    "71A#0401000105000201",  # transmit and bus
    "71A#05" + _PACKED,  # deadlines
    "41A#8009010002FA0046",  # admission verdict: request
    "41A#8009280003FA0046",  # admission verdict: a one-shot request (unit 3), analysed every 40 ms
    "41A#8106D00700E80300",  # admission verdict: bound
]

# Signals with no field in `amiro decode --json`, and why.
NOT_IN_JSON = {
    "key",  # the shutdown key: amiro checks it, it is not a value
}


def amiro(*args, stdin=None):
    result = subprocess.run(
        [AMIRO, *args], input=stdin, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, f"amiro {' '.join(args)} failed: {result.stderr}"
    return result.stdout


def split(frame):
    ident, data = frame.split("#")
    return int(ident, 16), bytes.fromhex(data)


def flatten(values, prefix=""):
    """amiro's JSON values as flat signal names: nested objects join with `_`, lists count from 1."""
    flat = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "_"))
        elif isinstance(value, list):
            for i, item in enumerate(value, start=1):
                flat[f"{name}_{i}"] = item
        else:
            flat[name] = value
    return flat


def comparable(value):
    if isinstance(value, cantools.database.namedsignalvalue.NamedSignalValue):
        return value.name
    if value is None:
        return "none"
    if isinstance(value, bool):
        return int(value)
    return value


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    base = os.environ.get("AMIRO_INTEROP_DIR")
    if base:
        path = Path(base) / "run"
        shutil.rmtree(path, ignore_errors=True)
        path.mkdir(parents=True)
        return path
    return tmp_path_factory.mktemp("interop")


@pytest.fixture(scope="module")
def database(workdir):
    path = workdir / "amiro.dbc"
    amiro("dbc", "--output", str(path))
    return cantools.database.load_file(str(path), strict=True)


def test_the_dbc_has_every_identifier(database):
    ids = {message.frame_id for message in database.messages}
    topics = [line.split()[0] for line in amiro("topics").splitlines()[1:]]
    assert len(topics) > 0
    for topic in topics:
        byte = int(topic, 16)
        for priority in range(4):
            assert (priority << 8 | byte) in ids, f"no command message for topic {topic}"
    assert 0x205 in ids and 0x605 in ids and 0x41A in ids


def test_cantools_decodes_like_amiro(database):
    records = [
        json.loads(line)
        for line in amiro("decode", "--json", stdin="\n".join(FRAMES) + "\n").splitlines()
    ]
    assert len(records) == len(FRAMES)
    compared = 0
    for frame, record in zip(FRAMES, records):
        assert record["ok"], f"amiro cannot decode {frame}: {record}"
        ident, data = split(frame)
        message = database.get_message_by_frame_id(ident)
        decoded = message.decode(data, decode_choices=True, allow_truncated=True)
        expected = flatten(record.get("values") or record["command"])
        multiplexers = {s.name for s in message.signals if s.is_multiplexer}
        for name, value in decoded.items():
            if name in multiplexers and name not in expected:
                continue
            if name in NOT_IN_JSON:
                continue
            assert name in expected, f"{frame}: cantools gives {name}, amiro prints {sorted(expected)}"
            assert comparable(value) == comparable(expected[name]), (
                f"{frame} ({message.name}): {name} is {value!r} in cantools, {expected[name]!r} in amiro"
            )
            compared += 1
    assert compared >= 3 * len(FRAMES) // 2


def test_cantools_encodes_what_amiro_decodes(database):
    message = database.get_message_by_name("gyroscope_high")
    data = message.encode({"x_dps": -4, "y_dps": 30, "z_dps": 5})
    frame = f"{message.frame_id:03X}#{data.hex().upper()}"
    assert frame == "508#FCFF1E000500"
    record = json.loads(amiro("decode", "--json", frame))
    assert record["values"] == {"x_dps": -4, "y_dps": 30, "z_dps": 5}


@pytest.fixture(scope="module")
def sent_log(workdir):
    path = workdir / "sent.log"
    path.unlink(missing_ok=True)
    amiro("send", *[f for f in FRAMES], "--bus", f"file:{path}")
    return path


def test_python_can_reads_the_log_amiro_writes(sent_log):
    messages = list(can.CanutilsLogReader(str(sent_log)))
    assert [(m.arbitration_id, bytes(m.data)) for m in messages] == [split(f) for f in FRAMES]
    assert all(not m.is_extended_id and not m.is_remote_frame for m in messages)
    timestamps = [m.timestamp for m in messages]
    assert timestamps == sorted(timestamps)


def test_amiro_reads_the_log_python_can_writes(workdir):
    path = workdir / "python-can.log"
    with can.CanutilsLogWriter(str(path), channel="can0") as writer:
        for i, frame in enumerate(FRAMES):
            ident, data = split(frame)
            writer.on_message_received(
                can.Message(timestamp=1.0 + i / 1000, arbitration_id=ident, data=data, is_extended_id=False)
            )
    records = [json.loads(line) for line in amiro("decode", "--json", "--file", str(path)).splitlines()]
    assert [r["frame"] for r in records] == FRAMES
    assert all(r["ok"] for r in records)


def test_can_utils_read_the_log_amiro_writes(sent_log):
    long = subprocess.run(
        ["log2long"], stdin=sent_log.open(), capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert len(long) == len(FRAMES)
    for line, frame in zip(long, FRAMES):
        ident, data = split(frame)
        fields = line.split()
        assert fields[1] == "can0" and int(fields[2], 16) == ident, line
        assert fields[3] == f"[{len(data)}]", line
        assert bytes.fromhex("".join(fields[4 : 4 + len(data)])) == data, line
    asc = subprocess.run(
        ["log2asc", "-I", str(sent_log), "can0"], capture_output=True, text=True, check=True
    ).stdout
    rows = [line.split() for line in asc.splitlines() if " Rx " in line]
    assert [(int(r[2], 16), bytes.fromhex("".join(r[6:]))) for r in rows] == [split(f) for f in FRAMES]


def qemu_bus_logs():
    root = os.environ.get("AMIRO_QEMU_SCENARIOS")
    return sorted(Path(root).glob("*/*/bus.log")) if root else []


def test_other_tools_read_the_bus_logs_cargo_xtask_qemu_writes():
    logs = qemu_bus_logs()
    if not os.environ.get("AMIRO_QEMU_SCENARIOS"):
        pytest.skip("run by cargo xtask test after the QEMU scenarios")
    assert logs, "no bus.log from the QEMU scenarios"
    for path in logs:
        text_frames = [line.split()[2] for line in path.read_text().splitlines() if line.strip()]
        messages = list(can.CanutilsLogReader(str(path)))
        assert [(m.arbitration_id, bytes(m.data)) for m in messages] == [split(f) for f in text_frames], path
        long = subprocess.run(["log2long"], stdin=path.open(), capture_output=True, text=True, check=True)
        assert len(long.stdout.splitlines()) == len(text_frames), path
