#!/usr/bin/env python3
"""Feeds stdin to unstamped.py and records.py (argv: the ELF), writing unstamped.txt and records.txt."""
import os
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
elf = sys.argv[1]
children = [subprocess.Popen([sys.executable, os.path.join(here, script), elf], stdin=subprocess.PIPE,
                             stdout=open(out, "w"), stderr=subprocess.STDOUT)
            for script, out in (("unstamped.py", "unstamped.txt"), ("records.py", "records.txt"))]
src = sys.stdin.buffer
while True:
    chunk = src.read(1 << 20)
    if not chunk:
        break
    for c in children:
        c.stdin.write(chunk)
for c in children:
    c.stdin.close()
    c.wait()
