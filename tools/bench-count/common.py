"""Shared by unstamped.py and records.py: symbols and instruction addresses of a traced QEMU image."""
import re
import subprocess


def symbols(elf):
    """(address, size, demangled name) of every function symbol."""
    nm = subprocess.run(["llvm-nm", "-S", "--demangle", elf], capture_output=True, text=True, check=True).stdout
    out = []
    for line in nm.splitlines():
        p = line.split(None, 3)
        if len(p) == 4 and p[2] in "tTwW":
            out.append((int(p[0], 16), int(p[1], 16), p[3]))
    return out


def sym(syms, pat):
    for a, n, name in syms:
        if re.search(pat, name):
            return a, n
    raise SystemExit(f"no symbol {pat}")


def disassemble(elf, start=None, size=None):
    """(address, mnemonic, operands) of the instructions of [start, start + size), or of the whole image."""
    args = ["llvm-objdump", "-d", "--no-show-raw-insn", "--demangle"]
    if start is not None:
        args += [f"--start-address={start:#x}", f"--stop-address={start + size:#x}"]
    out = []
    for line in subprocess.run(args + [elf], capture_output=True, text=True, check=True).stdout.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s+(\S+)\s*(.*)", line)
        if m and not m.group(2).startswith("."):
            out.append((int(m.group(1), 16), m.group(2), m.group(3)))
    return out


def record_read(elf, syms):
    """A task record's stamp in `tracing::write` (periodic clock, `qemu::timer::now_cycles` inlined): the read of
    SysTick's counter between two looks at the tick count (the first load after the first call of `now_ticks`),
    and the instruction after the loop's `bne` back (the read before it is the stamp). (read, loop exit)."""
    a, n = sym(syms, r"^amiro_firmware::tracing::write::")
    insns = disassemble(elf, a, n)
    i = next(k for k, x in enumerate(insns) if x[1] == "bl" and "now_ticks" in x[2])
    read_at = next(x[0] for x in insns[i:] if x[1].startswith("ldr"))
    j = next(k for k, x in enumerate(insns[i:], i) if x[1].startswith("bne"))
    return read_at, insns[j + 1][0]


def tick_read(elf, syms):
    """SysTick's own stamps (`qemu::timer::tick_cycles`, called twice by a busy tick): the function's entry and its
    read of SysTick's counter (CVR, 8 bytes above the status register: the first `ldr …, #8]`); the last read of
    a call is its stamp. (entry, read)."""
    a, n = sym(syms, r"^amiro_firmware::qemu::timer::tick_cycles::")
    return a, next(x[0] for x in disassemble(elf, a, n) if x[1].startswith("ldr") and x[2].endswith("#8]"))


def semihosting_calls(elf):
    """Addresses of every semihosting call (`bkpt 0xab`)."""
    return {a for a, op, rest in disassemble(elf) if op == "bkpt" and "0xab" in rest}
