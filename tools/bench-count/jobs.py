#!/usr/bin/env python3
"""Per task run of a traced single-board QEMU run, its own instructions between its start and end stamps, at its own
level (the exceptions nested in it, the runs that pre-empted it and the ticks, are counted to themselves), less its
records' and its handler events' parts at their fewest (486, and 1 617 per event: records.py, the figures of
xtask/src/bench/machine.rs): at most what its own code ran, to set beside a job the bench prints `NOT HELD`
(docs/bench.md, "What the check holds").

stdin: QEMU's `-singlestep -d exec,nochain,int` log (as run.sh runs it). argv: the ELF that ran, a regular expression
of function names: the exceptions (dispatchers or handlers) with a run that entered one of them are listed, each with
its runs' events and its largest runs."""
import re
import sys
from collections import Counter

from common import record_read, sym, symbols

RECORDS_FEWEST, EVENT_FEWEST = 486, 1617
elf, mark = sys.argv[1], sys.argv[2]
syms = symbols(elf)
start_at, _ = sym(syms, r"^amiro_firmware::tracing::start::")
end_at, _ = sym(syms, r"^amiro_firmware::tracing::end::")
event_at, _ = sym(syms, r"^amiro_firmware::tracing::event::")
read_at, exit_at = record_read(elf, syms)
marks = {a for a, n, name in syms if re.search(mark, name)}
print(f"# {mark}: {len(marks)} functions", file=sys.stderr)


class Act:
    def __init__(s, exc):
        s.exc = exc; s.n = 0; s.armed = None; s.last_read = None; s.open = None; s.events = 0; s.hit = False


stack = [Act("thread")]
runs = []  # (exception, entered a marked function, events, own instructions between the stamps)
last_pc = None
for line in sys.stdin:
    if line.startswith("Trace "):
        a = line.find("/"); pc = int(line[a + 1:a + 9], 16); t = stack[-1]; t.n += 1; last_pc = pc
        if pc == start_at:
            t.armed = "start"
        elif pc == end_at:
            t.armed = "end"
        elif pc == read_at:
            t.last_read = t.n - 1
        elif pc == exit_at and t.armed:
            if t.armed == "start":
                t.open, t.events, t.hit = t.last_read, 0, False
            elif t.open is not None and t.last_read is not None:
                runs.append((t.exc, t.hit, t.events, t.last_read - t.open))
                t.open = None
            t.armed = None
        if t.open is not None:
            t.events += pc == event_at
            t.hit |= pc in marks
    elif line.startswith("cpu_io_recompile: rewound execution of TB to "):
        at = int(line.rsplit(" ", 1)[1], 16)
        if last_pc == at:
            t = stack[-1]; t.n -= 1; last_pc = None
            if at == read_at:
                t.last_read = None
    elif line.startswith("...taking pending nonsecure exception "):
        stack.append(Act(int(line.rsplit(" ", 1)[1])))
    elif line.startswith("Exception return: magic PC"):
        stack.pop()

own = lambda r: r[3] - RECORDS_FEWEST - r[2] * EVENT_FEWEST
for exc in sorted({r[0] for r in runs if r[1]}, key=str):
    same = [r for r in runs if r[0] == exc]
    print(f"exception {exc}: {len(same)} runs ({sum(r[1] for r in same)} entered {mark}), "
          f"events per run {dict(sorted(Counter(r[2] for r in same).items()))}")
    for r in sorted(same, key=lambda r: -own(r))[:5]:
        print(f"  own between its stamps {r[3]}, {r[2]} events: at most {own(r)} of its own code")
