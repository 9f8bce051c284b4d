"""The live emulated robot for the interop tests: `cargo xtask robot --slcan …` started (AMIRO_XTASK is the xtask
binary), its SLCAN pseudo-terminal found, its output drained while a test talks to it (a full pipe would stall the
run), and stopped as a user would, with Ctrl-C."""

import contextlib
import os
import signal
import subprocess
import threading
import time

import pytest

XTASK = os.environ.get("AMIRO_XTASK")


@contextlib.contextmanager
def live_robot(*extra):
    """Starts `xtask robot --slcan --duration 120s EXTRA…`; yields (port, result). When the block ends the run is
    stopped and `result` gets its stdout lines after the port line (`lines`) and its stderr (`stderr`); the run must
    end with status 0."""
    if not XTASK:
        pytest.skip("AMIRO_XTASK names no xtask binary")
    proc = subprocess.Popen(
        [XTASK, "robot", "--slcan", "--duration", "120s", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    port = None
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if line.startswith("slcan: "):
            port = line.split(" ", 1)[1].strip()
            break
    assert port and port.startswith("/dev/pts/"), "no `slcan: /dev/pts/N` line"
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    result = {}
    try:
        yield port, result
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=120)
        reader.join(timeout=60)
        result["stderr"] = proc.stderr.read()
        result["lines"] = lines
    assert proc.returncode == 0, result["stderr"]
