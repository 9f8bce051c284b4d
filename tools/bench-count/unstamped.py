#!/usr/bin/env python3
"""Per exception activation of a traced single-board QEMU run, the instructions it executes outside the stamped
spans of the runs in it (its own level only: nested exceptions are counted to themselves): the figures
`QEMU_PREEMPTION_BY_{HANDLER,DISPATCHER,CLOCK}_{FEWEST,SPREAD}_INSTRUCTIONS` of xtask/src/bench/machine.rs.

stdin: QEMU's `-singlestep -d exec,nochain,int` log (run.sh). argv: the ELF that ran.

A task run's start stamp is the last read of SysTick's counter in `tracing::write`'s read loop
(`common.record_read`) after `tracing::start` was entered at that level, its end stamp the same after `tracing::end`.
A busy tick of SysTick (exception 15) calls `qemu::timer::tick_cycles` twice: its stamps are each call's last read
of the counter (`common.tick_read`); a tick without them is a plain tick, counted whole. Per activation with k >= 1
runs: the instructions before the first start stamp (entry), between an end stamp and the next start stamp (gap,
per pair), after the last end stamp (exit); per run (entry + gaps + exit) / k."""
import sys
from collections import Counter, defaultdict

from common import record_read, sym, symbols, tick_read

elf = sys.argv[1]
syms = symbols(elf)
start_at, _ = sym(syms, r"^amiro_firmware::tracing::start::")
end_at, _ = sym(syms, r"^amiro_firmware::tracing::end::")
read_at, exit_at = record_read(elf, syms)
tick_at, tick_cvr = tick_read(elf, syms)
print(f"# start {start_at:#x} end {end_at:#x} record read {read_at:#x} loop exit {exit_at:#x} "
      f"tick_cycles {tick_at:#x} its read {tick_cvr:#x}", file=sys.stderr)


class Act:
    __slots__ = ("exc", "n", "armed", "last_read", "stamps", "calls")

    def __init__(self, exc):
        self.exc = exc
        self.n = 0            # own instructions so far
        self.armed = None     # 'start' / 'end' after entering that function
        self.last_read = None
        self.stamps = []      # (kind, own index of the clock read)
        self.calls = []       # SysTick: per call of tick_cycles, the own index of its last read


stack = [Act("thread")]
last_pc = None
results = defaultdict(list)  # exc -> list of (k, entry, gaps, exit)
plain = Counter()  # plain ticks: their whole instruction counts
bad = 0


def close(act):
    global bad
    if act.exc == 15:
        if not act.calls:
            plain[act.n] += 1
            return
        if len(act.calls) != 2 or None in act.calls:
            bad += 1
            return
        act.stamps = [("start", act.calls[0]), ("end", act.calls[1])]
    if not act.stamps:
        return
    kinds = [k for k, _ in act.stamps]
    if kinds != ["start", "end"] * (len(kinds) // 2) or len(kinds) % 2:
        bad += 1
        return
    pos = [p for _, p in act.stamps]
    entry = pos[0]
    exit_ = act.n - pos[-1] - 1
    gaps = [pos[2 * r + 2] - pos[2 * r + 1] - 1 for r in range(len(pos) // 2 - 1)]
    results[act.exc].append((len(pos) // 2, entry, gaps, exit_))


for line in sys.stdin:
    if line.startswith("Trace "):
        a = line.find("/")
        pc = int(line[a + 1:a + 9], 16)
        top = stack[-1]
        top.n += 1
        last_pc = pc
        if pc == start_at:
            top.armed = "start"
        elif pc == end_at:
            top.armed = "end"
        elif pc == read_at:
            top.last_read = top.n - 1
        elif pc == exit_at and top.armed:
            top.stamps.append((top.armed, top.last_read))
            top.armed = None
        elif pc == tick_at and top.exc == 15:
            top.calls.append(None)
        elif pc == tick_cvr and top.exc == 15 and top.calls:
            top.calls[-1] = top.n - 1
    elif line.startswith("cpu_io_recompile: rewound execution of TB to "):
        at = int(line.rsplit(" ", 1)[1], 16)
        if last_pc == at:
            top = stack[-1]
            top.n -= 1  # logged again when re-executed
            if at == read_at:
                top.last_read = None
            elif at == tick_cvr and top.calls and top.calls[-1] == top.n:
                top.calls[-1] = None
            last_pc = None
    elif line.startswith("...taking pending nonsecure exception "):
        stack.append(Act(int(line.rsplit(" ", 1)[1])))
    elif line.startswith("Exception return: magic PC"):
        prev = int(line.rsplit(" ", 1)[1])
        act = stack.pop()
        if act.exc != prev:
            print(f"# stack mismatch {act.exc} {prev}", file=sys.stderr)
        close(act)

print(f"# activations with runs out of order: {bad}")
for exc, rows in sorted(results.items(), key=lambda r: str(r[0])):
    totals = [(e + sum(g) + x, k) for k, e, g, x in rows]
    entries = Counter(e for _, e, _, _ in rows)
    exits = Counter(x for _, _, _, x in rows)
    gaps = Counter(g for _, _, gs, _ in rows for g in gs)
    ks = Counter(k for k, _, _, _ in rows)
    print(f"exception {exc}{' (SysTick: the platform clock)' if exc == 15 else ''}: {len(rows)} activations, "
          f"runs per activation {dict(sorted(ks.items()))}")
    print(f"  entry (before the first start stamp): min {min(entries)} max {max(entries)} {sorted(entries.items())[:5]}")
    print(f"  exit (after the last end stamp): min {min(exits)} max {max(exits)} {sorted(exits.items())[:5]}")
    if gaps:
        print(f"  gap (end stamp to next start stamp): min {min(gaps)} max {max(gaps)} {sorted(gaps.items())[:5]}")
    single = [e + x for k, e, _, x in rows if k == 1]
    print(f"  per run: min {min(t // k for t, k in totals)} max {max(-(-t // k) for t, k in totals)}; "
          f"entry+exit of single-run activations min {min(single, default=None)} max {max(single, default=None)}")
if plain:
    print(f"plain ticks (SysTick without stamps, whole): {sum(plain.values())}, min {min(plain)} max {max(plain)} "
          f"{sorted(plain.items())[:6]} … {sorted(plain.items())[-4:]}")
