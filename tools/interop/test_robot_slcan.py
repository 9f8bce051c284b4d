"""The emulated robot (`cargo xtask robot --slcan`) is an SLCAN adapter to the tools that drive a real one:
python-can's `slcan` interface and `amiro` send a magnetometer command through its pseudo-terminal and hear
DiWheelDrive's magnetometer frames come back from the three boards running in QEMU. The command asks for
magnetometer-x every 6 ms at medium, admitted on both robot revisions: its frames take 3 479.9 µs on a 1-1 robot
(whose polled HMC5883L makes a magnetometer-x job 1.35 ms with its reads' transaction caps, and whose frames wait
behind a transmit job of their own; the shortest period 3 572 µs) and 1 800.4 µs on a 1-2 one (`cargo xtask
analyze`, 2026-12-06; docs/analysis.md). The thesis's 900 µs is refused on both, and so was 1.3 ms on a 1-1 robot
from 2026-12-06.

Run by `cargo xtask test` (xtask/src/interop.rs: AMIRO_XTASK is the xtask binary); by hand:
    AMIRO=target/debug/amiro AMIRO_XTASK=target/debug/xtask python -m pytest tools/interop/test_robot_slcan.py
"""

import os
import subprocess
import time

import can
import pytest

from live_robot import live_robot

AMIRO = os.environ.get("AMIRO", "amiro")


@pytest.fixture(scope="module")
def robot():
    with live_robot() as (port, result):
        yield port
    assert "bus log (candump -l): " in result["stderr"]
    assert any(line.startswith("diwheeldrive: # qemu: end of run") for line in result["lines"])


def test_python_can_commands_the_robot(robot):
    bus = can.Bus(interface="slcan", channel=robot, bitrate=1_000_000)
    try:
        bus.send(can.Message(arbitration_id=0x205, data=[0x01, 0x06, 0x00, 0x00], is_extended_id=False))
        seen = []
        deadline = time.monotonic() + 60
        while len(seen) < 5 and time.monotonic() < deadline:
            msg = bus.recv(timeout=1)
            if msg is not None and msg.arbitration_id == 0x605:
                seen.append(msg)
        assert len(seen) == 5, f"{len(seen)} magnetometer frames from the emulated DiWheelDrive"
        assert all(m.dlc == 4 and not m.is_extended_id for m in seen)
        # Stop it again: the next test starts from a quiet robot.
        bus.send(can.Message(arbitration_id=0x205, data=[0x00], is_extended_id=False))
    finally:
        bus.shutdown()


def test_amiro_sends_and_monitors(robot):
    sent = subprocess.run(
        [AMIRO, "send", "205#01060000", "--bus", f"slcan:{robot}"], capture_output=True, text=True, timeout=60
    )
    assert sent.returncode == 0, sent.stderr
    heard = subprocess.run(
        [AMIRO, "monitor", "--bus", f"slcan:{robot}", "--count", "3", "--timeout", "60s", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert heard.returncode == 0, heard.stderr
    lines = [l for l in heard.stdout.splitlines() if l.strip()]
    assert len(lines) == 3, heard.stdout
    assert all("magnetometer" in l for l in lines), heard.stdout
