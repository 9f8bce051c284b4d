//! The cycle model: what one instruction costs on the core, and what the memory system adds, for the
//! two chips of the robot. Every figure is stated with its source in docs/analysis.md
//! ("Execution-time bounds from the machine code").
use serde::Serialize;

use super::values::{State, Value};
use crate::decode::{Flow, Insn, Opcode, Operand, PC, SP};
use crate::Error;
use yaxpeax_arm::armv7::{RegShiftStyle, ShiftStyle};

/// The pipeline refill after a taken branch: the TRMs give P as 1 to 3 cycles; taken at its
/// maximum.
pub const P: u64 = 3;
/// Integer division: 2 to 12 cycles (M3 and M4 TRMs), taken at 12.
pub const DIVIDE: u64 = 12;
/// Exception entry (12 cycles) and return (10 cycles) on both cores, tail-chaining not assumed.
pub const EXCEPTION_ENTRY: u64 = 12;
pub const EXCEPTION_EXIT: u64 = 10;
/// Lazy FPU state preservation on the M4F: the 17 extended-frame words (s0-s15, FPSCR) pushed when
/// a handler first uses the FPU, one cycle each.
pub const LAZY_FPU_STACKING: u64 = 17;
/// Barriers (`DMB`, `DSB`, `ISB`): 1 + B; B taken as a pipeline refill (an `ISB` flushes it).
pub const BARRIER: u64 = 1 + P;

/// The chip an image runs on, with its flash wait states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Chip {
    /// STM32F103 (Cortex-M3) at 72 MHz; flash behind a 2 × 64-bit prefetch buffer (2 wait states
    /// at 72 MHz, RM0008 §3.3.3).
    Stm32f103 { wait_states: u32 },
    /// STM32F405 (Cortex-M4F) at 168 MHz; flash behind the ART accelerator's 128-bit lines (5 wait
    /// states at 168 MHz and 3.3 V, RM0090 §3.5.1).
    Stm32f405 { wait_states: u32 },
}

/// Where a load or store goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Region {
    /// Flash (the code region, 0x0000_0000..0x2000_0000; the STM32 maps flash at 0x0800_0000 and
    /// aliases it at 0).
    Flash,
    /// SRAM (0x2000_0000..0x4000_0000) and the stack.
    Ram,
    /// A peripheral on APB1, APB2 or AHB (0x4000_0000..0x6000_0000).
    Apb1,
    Apb2,
    Ahb,
    /// The core's private peripherals (NVIC, SysTick, DWT: 0xE000_0000..).
    Private,
    /// Not known from the machine code: charged the worst of the others.
    Unknown,
}

impl Chip {
    /// The chip of a `--chip` name (`stm32f103`, `stm32f405`), with its default wait states unless
    /// `wait_states` overrides them.
    pub fn parse(name: &str, wait_states: Option<u32>) -> Result<Chip, Error> {
        match name.to_ascii_lowercase().as_str() {
            "stm32f103" | "f103" => Ok(Chip::Stm32f103 {
                wait_states: wait_states.unwrap_or(2),
            }),
            "stm32f405" | "f405" => Ok(Chip::Stm32f405 {
                wait_states: wait_states.unwrap_or(5),
            }),
            other => Err(Error::Other(format!(
                "unknown chip `{other}` (known: stm32f103, stm32f405)"
            ))),
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Chip::Stm32f103 { .. } => "STM32F103",
            Chip::Stm32f405 { .. } => "STM32F405",
        }
    }

    /// The core clock the boards run it at.
    pub fn clock_hz(self) -> u64 {
        match self {
            Chip::Stm32f103 { .. } => 72_000_000,
            Chip::Stm32f405 { .. } => 168_000_000,
        }
    }

    /// Flash wait states.
    pub fn wait_states(self) -> u64 {
        match self {
            Chip::Stm32f103 { wait_states } | Chip::Stm32f405 { wait_states } => {
                u64::from(wait_states)
            }
        }
    }

    /// Bytes of one flash line the core's fetch reads at once (prefetch buffer: 64 bits; ART: 128).
    pub fn line_bytes(self) -> u64 {
        match self {
            Chip::Stm32f103 { .. } => 8,
            Chip::Stm32f405 { .. } => 16,
        }
    }

    /// Whether the core is a Cortex-M4 (single-cycle long multiply and multiply-accumulate, FPU).
    pub fn m4(self) -> bool {
        matches!(self, Chip::Stm32f405 { .. })
    }

    /// Exception entry and exit of a handler, with lazy FPU stacking on the M4F.
    pub fn exception_cycles(self) -> u64 {
        EXCEPTION_ENTRY + EXCEPTION_EXIT + if self.m4() { LAZY_FPU_STACKING } else { 0 }
    }

    /// Cycles as nanoseconds at the chip's clock, rounded up. Worked in 128 bits: a bound beyond about 18 G cycles
    /// (the admission step's, whose stated totals reach hundreds of G cycles) overflows the 64-bit product; a result
    /// beyond 64 bits (above 10^18 cycles) saturates.
    pub fn cycles_to_ns(self, cycles: u64) -> u64 {
        let ns = (u128::from(cycles) * 1_000_000_000).div_ceil(u128::from(self.clock_hz()));
        u64::try_from(ns).unwrap_or(u64::MAX)
    }

    /// Nanoseconds as cycles at the chip's clock, rounded up (in 128 bits, as [`Chip::cycles_to_ns`]).
    pub fn ns_to_cycles(self, ns: u64) -> u64 {
        let cycles = (u128::from(ns) * u128::from(self.clock_hz())).div_ceil(1_000_000_000);
        u64::try_from(cycles).unwrap_or(u64::MAX)
    }

    /// Which region an address is in (the STM32F1/F4 memory maps, RM0008 §3.3 and RM0090 §2.3).
    pub fn region(self, address: u32) -> Region {
        match address {
            0..=0x1fff_ffff => Region::Flash,
            0x2000_0000..=0x3fff_ffff => Region::Ram,
            0x4000_0000..=0x4000_ffff => Region::Apb1,
            0x4001_0000..=0x4001_7fff => Region::Apb2,
            0x4001_8000..=0x4001_ffff => match self {
                Chip::Stm32f103 { .. } => Region::Ahb,
                Chip::Stm32f405 { .. } => Region::Apb2,
            },
            0x4002_0000..=0x5fff_ffff => Region::Ahb,
            0xe000_0000..=0xe00f_ffff => Region::Private,
            _ => Region::Unknown,
        }
    }

    /// Cycles one access to `region` adds to the instruction's own: flash wait states for a data
    /// read from flash; for a peripheral, the bus's stated latency (docs/analysis.md: two clocks of
    /// the APB bus per transfer, AMBA APB protocol, plus one cycle of the bridge, at the chip's
    /// prescalers: F103 APB1 = HCLK/2, APB2 = HCLK; F405 APB1 = HCLK/4, APB2 = HCLK/2).
    pub fn access_cycles(self, region: Region) -> u64 {
        let (apb1, apb2) = match self {
            Chip::Stm32f103 { .. } => (2 * 2 + 1, 2 + 1),
            Chip::Stm32f405 { .. } => (2 * 4 + 1, 2 * 2 + 1),
        };
        match region {
            Region::Flash => self.wait_states(),
            Region::Ram => 0,
            Region::Apb1 => apb1,
            Region::Apb2 => apb2,
            Region::Ahb | Region::Private => 1,
            Region::Unknown => apb1.max(self.wait_states()),
        }
    }

    /// The cycles of one instruction on the core (pipeline refill of an always-taken branch and the
    /// refill of its first flash line included; a conditional branch's taken cost is
    /// [`Chip::taken_cycles`], on its edge), without its memory accesses.
    pub fn core_cycles(self, insn: &Insn) -> u64 {
        let refill = P + self.wait_states();
        let list = u64::from(insn.register_list().unwrap_or(0).count_ones());
        let m4 = self.m4();
        let flow = insn.flow();
        let transfer = match flow {
            Flow::Call(_) | Flow::IndirectCall(_) | Flow::Return | Flow::IndirectJump => refill,
            Flow::Branch(_) if !insn.conditional => refill,
            Flow::Table { .. } => refill,
            _ => 0,
        };
        let own = match insn.inst.opcode {
            Opcode::LDM(..) | Opcode::STM(..) | Opcode::PUSH | Opcode::POP => 1 + list.max(1),
            Opcode::LDRD | Opcode::STRD => 3,
            Opcode::LDR
            | Opcode::LDRB
            | Opcode::LDRH
            | Opcode::LDRSB
            | Opcode::LDRSH
            | Opcode::LDRT
            | Opcode::LDRBT
            | Opcode::LDRHT
            | Opcode::LDRSBT
            | Opcode::LDRSHT
            | Opcode::LDREX
            | Opcode::LDREXB
            | Opcode::LDREXH => 2,
            Opcode::STR
            | Opcode::STRB
            | Opcode::STRH
            | Opcode::STRT
            | Opcode::STRBT
            | Opcode::STRHT
            | Opcode::STREX
            | Opcode::STREXB
            | Opcode::STREXH => 2,
            Opcode::TBB | Opcode::TBH => 2,
            Opcode::UDIV | Opcode::SDIV => DIVIDE,
            Opcode::MLA | Opcode::MLS => {
                if m4 {
                    1
                } else {
                    2
                }
            }
            Opcode::UMULL | Opcode::SMULL => {
                if m4 {
                    1
                } else {
                    5
                }
            }
            Opcode::UMLAL | Opcode::SMLAL | Opcode::UMAAL => {
                if m4 {
                    1
                } else {
                    7
                }
            }
            Opcode::MSR | Opcode::MRS => 2,
            Opcode::DMB | Opcode::DSB | Opcode::ISB => BARRIER,
            _ => self.coprocessor_cycles(insn).unwrap_or(1),
        };
        own + transfer
    }

    /// Cycles of a floating-point instruction (the M4's FPU, coprocessors 10 and 11): `VLDR`/`VSTR`
    /// 2, `VLDM`/`VSTM`/`VPUSH`/`VPOP` 1 + N words, register moves 1 (2 for a pair), data processing
    /// at the slowest (`VDIV`, `VSQRT`: 14).
    fn coprocessor_cycles(self, insn: &Insn) -> Option<u64> {
        match insn.inst.opcode {
            Opcode::LDC(c, _) | Opcode::LDCL(c, _) | Opcode::STC(c, _) | Opcode::STCL(c, _)
                if c == 10 || c == 11 =>
            {
                let words = u64::from(insn.raw[1] & 0xff);
                // VLDR/VSTR (P = 1, W = 0) move one or two words in 2 cycles.
                let single = insn.raw[0] & 0x0120 == 0x0100;
                Some(if single { 2 } else { 1 + words.max(1) })
            }
            Opcode::MCRR(c, _, _) | Opcode::MRRC(c, _, _) if c == 10 || c == 11 => Some(2),
            Opcode::MCR(c, ..) | Opcode::MRC(c, ..) if c == 10 || c == 11 => Some(1),
            Opcode::CDP(c, ..) if c == 10 || c == 11 => Some(14),
            _ => None,
        }
    }

    /// What a conditional branch adds when it is taken: the pipeline refill and its first flash
    /// line.
    pub fn taken_cycles(self) -> u64 {
        P + self.wait_states()
    }

    /// The cycles fetching the code at `start..end` takes at least: every flash line it spans,
    /// each its wait states plus one (the prefetch fetches the next line while one executes, but
    /// no faster than that).
    pub fn fetch_cycles(self, start: u64, end: u64) -> u64 {
        if end <= start {
            return 0;
        }
        let line = self.line_bytes();
        ((end - 1) / line - start / line + 1) * (self.wait_states() + 1)
    }

    /// The memory cycles an instruction adds, given what is known of the registers before it
    /// ([`super::values`]): the accesses' count times the worst latency of any region the address
    /// may be in.
    pub fn memory_cycles(self, insn: &Insn, registers: &State) -> u64 {
        if !(insn.is_load() || insn.is_store()) {
            return 0;
        }
        let list = match insn.inst.opcode {
            Opcode::LDM(..) | Opcode::STM(..) | Opcode::PUSH | Opcode::POP => {
                Some(u64::from(insn.register_list().unwrap_or(0).count_ones()).max(1))
            }
            _ => None,
        };
        let fp = fp_span(insn);
        let words = match (fp, insn.inst.opcode) {
            (Some((n, _, _)), _) => n,
            (_, Opcode::LDRD | Opcode::STRD) => 2,
            _ => list.unwrap_or(1),
        };
        // The bytes past its address the access reaches (a word's 3, a doubleword's 7).
        let width = i64::try_from(insn.bytes_moved()).unwrap_or(4).max(1) - 1;
        let store = insn.is_store();
        let charge = |region: Region| {
            // Stores never go to flash in running code: an unknown store is a peripheral's at worst.
            let region = match region {
                Region::Flash | Region::Unknown if store => Region::Apb1,
                other => other,
            };
            self.access_cycles(region)
        };
        let base = base_register(insn);
        let worst = match base {
            Some(SP) => charge(Region::Ram),
            Some(PC) => charge(Region::Flash),
            _ => match base.map_or(Value::Unknown, |r| registers[usize::from(r)]) {
                Value::Stack => charge(Region::Ram),
                Value::Range(lo, hi) => {
                    // The accessed span: a list's words either side of its base, else the offset's.
                    // A floating-point transfer's words from its base (below it for a decrement).
                    let (from, to) = match (fp, list) {
                        (Some((_, a, b)), _) => (i64::from(lo) + a, i64::from(hi) + b),
                        (None, Some(n)) => {
                            (i64::from(lo) - 4 * n as i64, i64::from(hi) + 4 * n as i64)
                        }
                        (None, None) => match offsets(insn, registers) {
                            Some((a, b)) => (i64::from(lo) + a, i64::from(hi) + b + width),
                            // An index the analysis does not know, into the object its base
                            // addresses: the base's region, where the base is an address of the
                            // memory map (a small constant base is an offset, its index the pointer).
                            // Among the peripherals LLVM folds constants between base and
                            // index (a bus's start as the base, a negative index), so where a
                            // bus starts within 64 KiB of the base the index may reach it: the
                            // peripheral regions 64 KiB either side are charged. (RAM and flash
                            // objects lie in one region each, far from another's.)
                            None if (PERIPHERALS..PERIPHERALS_END).contains(&lo)
                                && (PERIPHERALS..PERIPHERALS_END).contains(&hi) =>
                            {
                                (
                                    (i64::from(lo) - NEAR).max(i64::from(PERIPHERALS)),
                                    (i64::from(hi) + NEAR + width)
                                        .min(i64::from(PERIPHERALS_END) - 1),
                                )
                            }
                            None if lo >= FIRST_ADDRESS => (i64::from(lo), i64::from(hi) + width),
                            None => (0, i64::from(u32::MAX)),
                        },
                    };
                    match wrapped(from, to) {
                        Some((low, high)) => {
                            let plain = self
                                .regions(low, high)
                                .into_iter()
                                .map(charge)
                                .max()
                                .unwrap_or_else(|| charge(Region::Unknown));
                            plain.max(self.bit_band_cycles(low, high, store))
                        }
                        None => charge(Region::Unknown),
                    }
                }
                Value::Unknown => charge(Region::Unknown),
            },
        };
        words * worst
    }

    /// The cycles an access to a bit-band alias in `low..=high` adds at worst (ARMv7-M ARM A3.7,
    /// the Cortex-M3 TRM §4.2: the SRAM alias 0x2200_0000-0x23ff_ffff and the peripheral alias
    /// 0x4200_0000-0x43ff_ffff address one bit each, word `n` of the alias bit `n % 8` of byte
    /// `n / 8` of the region's first MiB): the real byte's region on its own bus, and a store is a
    /// read-modify-write of it, two transfers and a cycle between; 0 where the range misses both.
    fn bit_band_cycles(self, low: u32, high: u32, store: bool) -> u64 {
        const ALIASES: [(u32, u32); 2] = [(0x2200_0000, 0x2000_0000), (0x4200_0000, 0x4000_0000)];
        let mut worst = 0;
        for (alias, real) in ALIASES {
            let end = alias + 0x01ff_ffff;
            if high < alias || low > end {
                continue;
            }
            let (a, b) = (low.max(alias), high.min(end));
            let (real_low, real_high) = (real + (a - alias) / 32, real + (b - alias) / 32);
            for region in self.regions(real_low, real_high) {
                let one = self.access_cycles(region);
                worst = worst.max(if store { 2 * one + 1 } else { one });
            }
        }
        worst
    }

    /// The regions any address of `low..=high` is in (the memory map of [`Chip::region`]).
    pub fn regions(self, low: u32, high: u32) -> Vec<Region> {
        // Where each region starts, in order; each runs to the next one's start.
        const STARTS: [u32; 9] = [
            0,
            0x2000_0000,
            0x4000_0000,
            0x4001_0000,
            0x4001_8000,
            0x4002_0000,
            0x6000_0000,
            0xe000_0000,
            0xe010_0000,
        ];
        let mut found = Vec::new();
        for (k, &start) in STARTS.iter().enumerate() {
            let end = STARTS.get(k + 1).map_or(u32::MAX, |&next| next - 1);
            if start <= high && low <= end {
                let region = self.region(start);
                if !found.contains(&region) {
                    found.push(region);
                }
            }
        }
        found
    }
}

/// The register a load or store addresses memory through: SP for `PUSH`/`POP`, the base of a
/// memory operand, or the base of a list's (`LDM Rn{!}`, `STMDB Rn!`, `VLDM`).
pub fn base_register(insn: &Insn) -> Option<u8> {
    match insn.inst.opcode {
        Opcode::PUSH | Opcode::POP => Some(SP),
        _ => insn.memory_base().or_else(|| {
            insn.inst.operands.iter().find_map(|o| match o {
                Operand::RegWBack(r, _) => Some(r.number()),
                _ => None,
            })
        }),
    }
}

/// A floating-point load or store (`LDC`/`STC` to coprocessor 10 or 11: `VLDR`, `VSTR`, `VLDM`,
/// `VSTM`, `VPUSH`, `VPOP`; ARMv7-M ARM A7.7.229-230, A7.7.255-256): the words it moves and the
/// first and last byte it reaches, as offsets from its base.
fn fp_span(insn: &Insn) -> Option<(u64, i64, i64)> {
    if insn.len != 4 || !(insn.is_coprocessor_load() || insn.is_coprocessor_store()) {
        return None;
    }
    let [hw1, hw2] = insn.raw;
    // hw1: 1110 110P UDWL Rn; hw2: Vd 101 sz imm8.
    let (p, u, w) = (hw1 & 0x0100 != 0, hw1 & 0x0080 != 0, hw1 & 0x0020 != 0);
    let imm8 = i64::from(hw2 & 0xff);
    if p && !w {
        // VLDR/VSTR: a single (one word) or a double (two) at ±imm8 words.
        let words = if hw2 & 0x0100 != 0 { 2 } else { 1 };
        let off = if u { 4 * imm8 } else { -4 * imm8 };
        return Some((words, off, off + 4 * words as i64 - 1));
    }
    // VLDM/VSTM: imm8 words from the base up (increment after) or below it (decrement before).
    let words = imm8.max(1);
    Some(if u {
        (words as u64, 0, 4 * words - 1)
    } else {
        (words as u64, -4 * words, -1)
    })
}

/// The peripheral buses' addresses (APB1, APB2, AHB: 0x4000_0000-0x5fff_ffff).
const PERIPHERALS: u32 = 0x4000_0000;
const PERIPHERALS_END: u32 = 0x6000_0000;

/// How far from its base an index the analysis does not know is taken to reach (64 KiB: the
/// memory map's regions start at multiples of it but APB2's end on the F103).
const NEAR: i64 = 0x1_0000;

/// The lowest address of the memory map's code, data and peripherals the images address (flash at
/// 0x0800_0000; below it only the boot alias of flash, which the code does not address).
const FIRST_ADDRESS: u32 = 0x0800_0000;

/// The least and largest offset a load or store adds to its base: its immediate (0 post-indexed),
/// or its index register's range, shifted left as the operand says and added or subtracted (the core
/// adds modulo 2³², so a constant index such as 0xffff_f800 is a negative offset: LLVM folds two
/// constants into base and index); `None` for an index register the analysis does not know (or
/// shifted other than left).
fn offsets(insn: &Insn, registers: &State) -> Option<(i64, i64)> {
    // An index operand: its register, left shift and sign (`None` inside: shifted otherwise).
    let index = insn.inst.operands.iter().find_map(|o| match *o {
        Operand::RegDerefPreindexReg(_, rm, add, _) => Some(Some((rm.number(), 0, add))),
        Operand::RegDerefPreindexRegShift(_, shift, add, _) => Some(match shift.into_shift() {
            RegShiftStyle::RegImm(s) if s.stype() == ShiftStyle::LSL => {
                Some((s.shiftee().number(), u32::from(s.imm()), add))
            }
            _ => None,
        }),
        _ => None,
    });
    match index {
        Some(None) => None,
        Some(Some((rm, shift, add))) => match registers[usize::from(rm)] {
            Value::Range(a, b) if shift <= 3 => {
                let (a, b) = (i64::from(a) << shift, i64::from(b) << shift);
                Some(if add { (a, b) } else { (-b, -a) })
            }
            _ => None,
        },
        None => {
            let k = insn.memory_offset().unwrap_or(0);
            Some((k, k))
        }
    }
}

/// The addresses `from..=to` modulo 2³², as one range of `u32`s; `None` when they wrap around or
/// cover every address.
fn wrapped(from: i64, to: i64) -> Option<(u32, u32)> {
    const SPAN: i64 = 1 << 32;
    if to - from >= SPAN {
        return None;
    }
    let low = from.rem_euclid(SPAN);
    let high = low + (to - from);
    (high < SPAN).then_some((low as u32, high as u32))
}

#[cfg(test)]
mod tests {
    use super::Chip;

    /// The admission step's bound (343 702 075 637 cycles on DiWheelDrive 1-1, 2026-12-05) overflowed the 64-bit
    /// product of the conversion; a result beyond 64 bits saturates.
    #[test]
    fn long_bounds_convert_without_overflow() {
        let f103 = Chip::Stm32f103 { wait_states: 2 };
        assert_eq!(f103.cycles_to_ns(72), 1_000);
        assert_eq!(f103.cycles_to_ns(343_702_075_637), 4_773_639_939_403);
        assert_eq!(f103.ns_to_cycles(4_773_639_939_403), 343_702_075_638);
        assert_eq!(f103.cycles_to_ns(u64::MAX), u64::MAX);
    }
}
