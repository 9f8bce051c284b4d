#!/usr/bin/env python3
"""The trace records' part inside a job's span in a traced single-board QEMU run: a start record from its clock
reading to `tracing::start`'s return, an end record from `tracing::end`'s entry to its clock reading, and each
handler event (`tracing::event`, whole): the figures `QEMU_RECORDS_FEWEST_INSTRUCTIONS` and
`QEMU_EVENT_FEWEST_INSTRUCTIONS` of xtask/src/bench/machine.rs. Counted per exception activation (nested
exceptions apart), twice: only the instructions inside the functions of FILTER (as QEMU's `-dfilter` on them
would: callees outside are not counted, so the figure is at most the true one; the figures use these), and all.

A record's stamp is the last read of SysTick's counter in `tracing::write`'s read loop (`common.record_read`).

stdin: QEMU's `-singlestep -d exec,nochain,int` log (run.sh). argv: the ELF that ran."""
import re
import sys
from collections import Counter

from common import disassemble, record_read, sym, symbols

FILTER = [r"^amiro_firmware::tracing::(start|end|event|emit|write)::", r"^amiro_trace::Encoder::(put|raw)::",
          r"^amiro_firmware::qemu::timer::now_ticks::", r"^amiro_firmware::qemu::console_write::",
          r"^cortex_m_semihosting::hio::HostStream::write_all::", r"^__aeabi_memclr8$"]
elf = sys.argv[1]
syms = symbols(elf)
ranges = [(a, a + n) for pat in FILTER for a, n, name in syms if re.search(pat, name)]
start_at, start_len = sym(syms, r"^amiro_firmware::tracing::start::")
end_at, _ = sym(syms, r"^amiro_firmware::tracing::end::")
event_at, event_len = sym(syms, r"^amiro_firmware::tracing::event::")
write_at, write_len = sym(syms, r"^amiro_firmware::tracing::write::")
for a, op, rest in disassemble(elf, write_at, write_len):  # the outlined helpers `write` calls
    m = re.search(r"<(OUTLINED_FUNCTION_\d+)>", rest)
    if op == "bl" and m:
        h, n = sym(syms, "^" + m.group(1) + "$")
        ranges.append((h, h + n))
read_at, _ = record_read(elf, syms)
start_ret = [a for a, op, rest in disassemble(elf, start_at, start_len) if op.startswith("pop") and "pc" in rest]
event_ret = [a for a, op, rest in disassemble(elf, event_at, event_len) if op.startswith("pop") and "pc" in rest]
print(f"# read {read_at:#x} start returns {[hex(x) for x in start_ret]} event returns {[hex(x) for x in event_ret]} "
      f"filter {len(ranges)} ranges", file=sys.stderr)


def inf(pc):
    return any(a <= pc < b for a, b in ranges)


class Act:
    def __init__(s, exc):
        s.exc = exc; s.mode = None; s.f = 0; s.a = 0; s.armed_start = False


stack = [Act("thread")]
parts = {k: (Counter(), Counter()) for k in ("start", "end", "event")}
last_pc = None
for line in sys.stdin:
    if line.startswith("Trace "):
        k = line.find("/"); pc = int(line[k + 1:k + 9], 16); t = stack[-1]; last_pc = pc
        if pc == start_at and t.mode is None:
            t.armed_start = True
        elif pc == end_at and t.mode is None:
            t.mode = "end"; t.f = t.a = 0
        elif pc == event_at and t.mode is None:
            t.mode = "event"; t.f = t.a = 0
        if t.mode == "end" and pc == read_at:
            parts["end"][0][t.f] += 1; parts["end"][1][t.a] += 1; t.mode = None
            continue
        if t.armed_start and pc == read_at and t.mode is None:
            t.armed_start = False; t.mode = "start"; t.f = t.a = 0
            continue
        if t.mode == "start" and pc == read_at:  # the read loop went round: the last read is the stamp
            t.f = t.a = 0
            continue
        if t.mode:
            t.a += 1
            if inf(pc):
                t.f += 1
            if t.mode == "start" and pc in start_ret:
                parts["start"][0][t.f] += 1; parts["start"][1][t.a] += 1; t.mode = None
            elif t.mode == "event" and pc in event_ret:
                parts["event"][0][t.f] += 1; parts["event"][1][t.a] += 1; t.mode = None
    elif line.startswith("cpu_io_recompile: rewound execution of TB to "):
        at = int(line.rsplit(" ", 1)[1], 16)
        if last_pc == at:
            t = stack[-1]
            if t.mode:
                t.a -= 1
                if inf(at):
                    t.f -= 1
            last_pc = None
    elif line.startswith("...taking pending nonsecure exception "):
        stack.append(Act(int(line.rsplit(" ", 1)[1])))
    elif line.startswith("Exception return: magic PC"):
        stack.pop()


def show(name, c):
    if c:
        print(f"{name}: n {sum(c.values())} min {min(c)} max {max(c)} fewest {sorted(c.items())[:5]}")


show("start record after the clock read (filtered)", parts["start"][0]); show("  all", parts["start"][1])
show("end record up to the clock read (filtered)", parts["end"][0]); show("  all", parts["end"][1])
show("event (filtered)", parts["event"][0]); show("  all", parts["event"][1])
if parts["start"][0] and parts["end"][0]:
    print("records fewest (filtered):", min(parts["start"][0]) + min(parts["end"][0]))
