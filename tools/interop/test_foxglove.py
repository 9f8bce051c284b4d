"""Foxglove's own WebSocket client (`@foxglove/ws-protocol`, Node) subscribes to `amiro monitor --foxglove` and
receives every channel with its JSON schema and each frame's values at the frame's time.

Run by `cargo xtask test` (xtask/src/interop.rs builds amiro with the `foxglove` feature); needs node and npm. By hand:
    cargo build -p operator --features foxglove
    AMIRO=target/debug/amiro python -m pytest tools/interop/test_foxglove.py
"""

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

AMIRO = os.environ.get("AMIRO", "amiro")
CLIENT = Path(__file__).parent / "foxglove-client"

# The gyroscope every 100 ms from 2 s on (the client connects and subscribes meanwhile), replayed at its pace.
START = 1_700_000_002
LOG = "(1700000000.000000) can0 108#01640000\n" + "".join(
    f"({START + i // 10}.{(i % 10) * 100000:06d}) can0 508#{(x & 0xFFFF).to_bytes(2, 'little').hex().upper()}1E00FBFF\n"
    for i, x in enumerate(range(-10, 10))
)


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    """The client installed from its pinned lock file."""
    if not shutil.which("node") or not shutil.which("npm"):
        pytest.fail("node and npm are needed for the Foxglove client check (Debian: apt-get install nodejs npm)")
    base = os.environ.get("AMIRO_INTEROP_DIR")
    work = Path(base) / "foxglove-client" if base else tmp_path_factory.mktemp("foxglove-client")
    work.mkdir(parents=True, exist_ok=True)
    for name in ["package.json", "package-lock.json", "client.js"]:
        shutil.copy(CLIENT / name, work / name)
    subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--silent"], cwd=work, check=True)
    return work


def test_foxglove_client_receives_the_bus_live(client, tmp_path):
    log = tmp_path / "gyro.log"
    log.write_text(LOG)
    amiro = subprocess.Popen(
        [AMIRO, "monitor", "--bus", f"file:{log}", "--realtime", "--no-summary", "--foxglove", "127.0.0.1:0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = amiro.stderr.readline()
        match = re.search(r"ws://127\.0\.0\.1:(\d+)", line)
        assert match, line
        url = f"ws://127.0.0.1:{match.group(1)}"
        result = subprocess.run(
            ["node", str(client / "client.js"), url, "4500"],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
        assert result.returncode == 0, result.stderr
    finally:
        amiro.wait(timeout=30)
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert records[0]["kind"] == "server" and records[0]["name"].startswith("amiro")
    channels = {r["topic"]: r for r in records if r["kind"] == "channel"}
    gyroscope = channels["/amiro/gyroscope"]
    assert gyroscope["encoding"] == "json" and gyroscope["schemaEncoding"] == "jsonschema"
    assert json.loads(gyroscope["schema"])["required"] == ["priority", "x_dps", "y_dps", "z_dps"]
    assert "/amiro/frames" in channels and "/amiro/power-status" in channels, "every topic before its data"

    samples = [r for r in records if r["kind"] == "message" and r["topic"] == "/amiro/gyroscope"]
    assert len(samples) == 20, samples
    for i, sample in enumerate(samples):
        assert sample["payload"] == {"priority": "high", "x_dps": -10 + i, "y_dps": 30, "z_dps": -5}
        assert int(sample["log_time"]) == START * 10**9 + i * 100_000_000
    frames = [r for r in records if r["kind"] == "message" and r["topic"] == "/amiro/frames"]
    assert frames[-1]["payload"]["frame"] == "508#09001E00FBFF"
