//! What instructions do to the interrupt masking, and the part of a function's graph a critical
//! section runs through ([`super::critical`] states the patterns): the raise and restore encodings,
//! the constant a raise writes (a forward data-flow pass), and the section's region as a graph of
//! its own, bounded as a function is.
use std::collections::BTreeMap;

use super::cfg::{Block, Cfg, Edge};
use crate::decode::{Flow, Insn, Opcode, Operand, Regs, LR, SP};
use crate::waits::Conditional;
use crate::Image;
use yaxpeax_arm::armv7::{RegShiftStyle, ShiftStyle};

/// The deepest nesting of raises of one kind a section is followed through.
const MAX_NESTING: u32 = 16;

/// The kinds of masking, nested apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Basepri,
    Primask,
    /// FAULTMASK set (`CPSID f`, `MSR FAULTMASK`): every interrupt waits, as with PRIMASK.
    Faultmask,
}

/// What an instruction does to the masking.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Effect {
    /// A raise: `MSR BASEPRI_MAX, rN` (the register), `MSR BASEPRI, rN` of a register that may hold
    /// a nonzero constant (the register), `CPSID i`/`f`, `MSR PRIMASK`/`FAULTMASK` of a register
    /// that may hold a constant with bit 0 set.
    Raise(Kind, Option<u8>),
    /// A restore: an `MSR` of a register that holds, on every path, what an `MRS` of the same mask
    /// register saved or a constant that clears the mask; `CPSIE i`/`f`.
    Restore(Kind),
    /// An `MSR` of the mask register `Kind` of a value the code does not fix (neither a saved mask
    /// nor a constant), or a `CPS` of PRIMASK and FAULTMASK at once: the task's section list is
    /// incomplete.
    Unclear(Kind),
}

// What a register may hold (a set of these), as the masking reads it.
/// What an `MRS` of PRIMASK saved.
const SAVED_PRIMASK: u8 = 1;
/// What an `MRS` of BASEPRI (or BASEPRI_MAX) saved.
const SAVED_BASEPRI: u8 = 1 << 1;
/// What an `MRS` of FAULTMASK saved.
const SAVED_FAULTMASK: u8 = 1 << 2;
/// The constant 0.
const ZERO: u8 = 1 << 3;
/// A constant with bit 0 set.
const ODD: u8 = 1 << 4;
/// A nonzero constant with bit 0 clear.
const EVEN: u8 = 1 << 5;
/// Anything else.
const OTHER: u8 = 1 << 6;
/// An address in the function's frame (SP, or a value worked from it).
const FRAME: u8 = 1 << 7;

/// Where a frame address is kept, for [`Known::widen`]'s count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Place {
    Register(u8),
    /// The frame's word at this offset from the entry's SP.
    Word(i32),
    /// [`Known::escaped`].
    Escaped,
}

/// What one register may hold at a point, on every path that reaches it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Holds {
    /// The kinds of value it may hold; none: no path reaches the point (yet).
    may: u8,
    /// The constant it holds on every path, where it is one.
    constant: Option<u32>,
    /// Where it may hold a frame address: the lowest offset from the entry's SP it may point to
    /// (an object in the frame is reached from its address upwards), `i32::MIN` where not fixed.
    low: i32,
}

impl Holds {
    const UNKNOWN: Holds = Holds {
        may: OTHER,
        constant: None,
        low: i32::MAX,
    };

    fn constant(v: u32) -> Holds {
        let may = match v {
            0 => ZERO,
            v if v & 1 == 1 => ODD,
            _ => EVEN,
        };
        Holds {
            may,
            constant: Some(v),
            low: i32::MAX,
        }
    }

    fn saved(kind: Kind) -> Holds {
        Holds {
            may: match kind {
                Kind::Primask => SAVED_PRIMASK,
                Kind::Basepri => SAVED_BASEPRI,
                Kind::Faultmask => SAVED_FAULTMASK,
            },
            constant: None,
            low: i32::MAX,
        }
    }

    fn meet(self, other: Holds) -> Holds {
        if self.may == 0 {
            return other;
        }
        if other.may == 0 {
            return self;
        }
        Holds {
            may: self.may | other.may,
            constant: if self.constant == other.constant {
                self.constant
            } else {
                None
            },
            low: self.low.min(other.low),
        }
    }

    /// A frame address pointing no lower than `low`.
    fn frame(low: i32) -> Holds {
        Holds {
            may: FRAME,
            constant: None,
            low,
        }
    }

    /// The lowest frame offset it may point to, where it may hold a frame address.
    fn frame_low(self) -> Option<i32> {
        (self.may & FRAME != 0).then_some(self.low)
    }
}

/// What the registers may hold before an instruction: [`Masks::entry`] of its block, stepped
/// through the block's instructions before it ([`Known::step`]). A mask an `MRS` saved is often
/// kept in the frame across the section (a spill): the words a store through SP wrote are followed
/// too, by their offset from SP at the function's entry, while SP's offset is fixed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Known {
    regs: [Holds; 16],
    /// SP's offset from its value at the function's entry, where the code fixes it.
    sp: Option<i32>,
    /// What the frame's words a store through SP wrote hold, by offset from the entry's SP.
    slots: BTreeMap<i32, Holds>,
    /// The lowest frame offset an address that has left the registers and words the pass follows
    /// (stored where it keeps no word of it, moved to a floating-point or special register,
    /// passed to a call) may point to: a store through any register, or a call, may write the
    /// frame's words from there up, and a word from there up may be read by code that has it.
    escaped: Option<i32>,
}

impl Known {
    /// At a function's entry: nothing fixed but SP's offset.
    fn entry() -> Known {
        Known {
            regs: [Holds::UNKNOWN; 16],
            sp: Some(0),
            slots: BTreeMap::new(),
            escaped: None,
        }
    }

    fn unreached() -> Known {
        Known {
            regs: [Holds::default(); 16],
            sp: None,
            slots: BTreeMap::new(),
            escaped: None,
        }
    }

    fn reached(&self) -> bool {
        self.regs[usize::from(SP)].may != 0
    }

    fn meet(&mut self, other: &Known) -> bool {
        if !other.reached() {
            return false;
        }
        if !self.reached() {
            *self = other.clone();
            return true;
        }
        let before = self.clone();
        for (a, b) in self.regs.iter_mut().zip(other.regs.iter()) {
            *a = a.meet(*b);
        }
        if self.sp != other.sp {
            self.sp = None;
            self.forget(|_| true);
        }
        let mut slots = BTreeMap::new();
        let mut lost = Vec::new();
        for (&at, &a) in self.slots.iter().chain(other.slots.iter()) {
            match (self.slots.get(&at), other.slots.get(&at)) {
                (Some(a), Some(b)) => {
                    slots.insert(at, a.meet(*b));
                }
                // A word kept on one path only: a frame address in it is no longer followed.
                _ => lost.extend(a.frame_low()),
            }
        }
        self.slots = slots;
        for low in lost {
            self.escape(low);
        }
        if let Some(low) = other.escaped {
            self.escape(low);
        }
        self.close();
        *self != before
    }

    /// After a join that changed the entry `old`: each lowest frame offset that went down (a
    /// register's, a word's, the escaped one) counts a step at its place (`lowered`, keyed by
    /// the place: a register, a word's offset, or the escaped address), and one that went down
    /// more than [`super::values::WIDEN_AFTER`] times goes to the bottom of the frame, so a
    /// pointer stepped down on every pass of a loop does not take a pass per step.
    fn widen(&mut self, old: &Known, mut lowered: impl FnMut(Place) -> u32) {
        let mut lower = |now: &mut Holds, was: &Holds, place: Place| {
            if let (Some(a), Some(b)) = (now.frame_low(), was.frame_low()) {
                if a < b && lowered(place) > super::values::WIDEN_AFTER {
                    now.low = i32::MIN;
                }
            }
        };
        for (r, (now, was)) in self.regs.iter_mut().zip(old.regs.iter()).enumerate() {
            lower(now, was, Place::Register(r as u8));
        }
        for (&at, now) in self.slots.iter_mut() {
            if let Some(was) = old.slots.get(&at) {
                lower(now, was, Place::Word(at));
            }
        }
        if let (Some(now), Some(was)) = (self.escaped, old.escaped) {
            if now < was && lowered(Place::Escaped) > super::values::WIDEN_AFTER {
                self.escaped = Some(i32::MIN);
            }
        }
    }

    /// Forgets the frame's words a store through an address not in the frame (or a call) may
    /// write: all where a frame address escaped.
    fn clobber_escaped(&mut self) {
        if let Some(low) = self.escaped {
            self.forget(|at| at + 4 > low);
        }
    }

    /// A call: a frame address among its arguments escapes to the callee — in r0-r3, or in a
    /// word of the frame the pass follows (the stack arguments are the words from SP up, and the
    /// code does not say how many the callee reads) — and the callee may write the frame's words
    /// from the lowest escaped address up.
    fn call_escapes(&mut self) {
        let low = (0..4u8)
            .filter_map(|r| self.frame(r))
            .chain(self.slots.values().filter_map(|held| held.frame_low()))
            .min();
        if let Some(low) = low {
            self.escape(low);
        }
        self.clobber_escaped();
    }

    /// A frame address that may point as low as `low` escapes, and with it every frame address a
    /// word from there up holds (code that has the one may load the other).
    fn escape(&mut self, low: i32) {
        let mut low = self.escaped.map_or(low, |e| e.min(low));
        while let Some(lower) = self
            .slots
            .iter()
            .filter(|&(&at, _)| at.saturating_add(4) > low)
            .filter_map(|(_, held)| held.frame_low())
            .filter(|&held| held < low)
            .min()
        {
            low = lower;
        }
        self.escaped = Some(low);
    }

    /// Lets escape every frame address a word an escaped address reaches holds.
    fn close(&mut self) {
        if let Some(low) = self.escaped {
            self.escape(low);
        }
    }

    /// Forgets the frame's words at the offsets `gone` picks: a frame address one held is no
    /// longer followed, so it has escaped.
    fn forget(&mut self, gone: impl Fn(i32) -> bool) {
        let mut lost = i32::MAX;
        self.slots.retain(|&at, held| {
            let keep = !gone(at);
            if !keep {
                lost = lost.min(held.frame_low().unwrap_or(i32::MAX));
            }
            keep
        });
        if lost != i32::MAX {
            self.escape(lost);
        }
    }

    /// The lowest frame offset register `r` may point to, where it may hold a frame address.
    fn frame(&self, r: u8) -> Option<i32> {
        if r == SP {
            return Some(self.sp.unwrap_or(i32::MIN));
        }
        self.regs[usize::from(r)].frame_low()
    }

    /// Forgets the frame's words `[at, at + bytes)` overlaps.
    fn clobber(&mut self, at: i32, bytes: i32) {
        self.forget(|w| w + 4 > at && w < at + bytes);
    }

    /// The frame after `insn`: SP's offset, the words it stores through SP, the addresses in the
    /// frame it takes. Returns what it loads from the frame into which registers.
    ///
    /// A frame address is either in a place the pass follows (a register, a word it keeps) or
    /// escaped: every instruction that moves a register's value elsewhere (a store the pass does
    /// not keep word by word, a floating-point or special register, a call, the debugger's
    /// semihosting block) lets a frame address in it escape, and a load the pass does not place
    /// word by word gives whatever frame address the words it may read hold.
    fn step_frame(&mut self, insn: &Insn) -> Vec<(u8, Holds)> {
        let opcode = insn.inst.opcode;
        let before = self.regs;
        let sp = self.sp;
        let base = base_of(insn);
        let base_sp = base == Some(SP);
        // A supervisor call runs a handler that, as a callee, may write through the pointers it
        // is given (the stacked r0-r3).
        let call = matches!(opcode, Opcode::BL | Opcode::BLX | Opcode::SVC);
        if call && insn.outlined.is_some() {
            // An outlined helper runs on its caller's frame and registers, follows no calling
            // convention, and may store anywhere in the frame any register it is given.
            let low = (0..16u8).filter_map(|r| self.frame(r)).min();
            self.forget(|_| true);
            if let Some(low) = low {
                self.escape(low);
            }
        } else if call {
            self.call_escapes();
        }
        if let Some(low) = moved_out(insn)
            .into_iter()
            .filter_map(|r| self.frame(r))
            .min()
        {
            self.escape(low);
        }
        if insn.is_semihosting() {
            // The debugger reads and writes memory through the block r1 points to.
            self.clobber_escaped();
        }
        let writes_sp = insn.writes().contains(SP) || writes_stack_pointer(insn);
        if insn.is_store() || insn.is_coprocessor_store() {
            let data: Vec<u8> = match insn.register_list() {
                Some(list) => (0..16u8).filter(|r| list & 1 << r != 0).collect(),
                None => insn.registers(),
            };
            let data_low = data.iter().filter_map(|&r| self.frame(r)).min();
            let placed = match (base_sp, sp) {
                (true, Some(sp)) => self.store_to_frame(insn, sp, &before),
                (true, None) => {
                    self.forget(|_| true);
                    false
                }
                (false, _) => {
                    if let Some(low) = data_low {
                        self.escape(low);
                    }
                    // Through a register that may hold a frame address: the words from its
                    // lowest address (moved by a negative offset, or a list stored below it)
                    // up; through any register, the words an escaped address reaches.
                    if let Some(low) = self.reached_from(insn, base) {
                        self.forget(|at| at + 4 > low);
                    }
                    self.clobber_escaped();
                    false
                }
            };
            // A frame address written where the pass keeps no word of it (a narrower, exclusive
            // or floating-point store, an offset it cannot compute, any store not through SP)
            // has escaped.
            if !placed {
                if let Some(low) = data_low {
                    self.escape(low);
                }
            }
        }
        let mut loaded: Vec<(u8, Holds)> = Vec::new();
        if insn.is_load() || insn.is_coprocessor_load() {
            let words = match (base_sp, sp) {
                (true, Some(sp)) => self.load_from_frame(insn, sp),
                _ => None,
            };
            match words {
                Some(words) => loaded = words,
                None => {
                    // Not placed word by word: through SP at an immediate offset it reads the
                    // words its (at most 8) bytes overlap; through a register that may hold a
                    // frame address, any word from that address's lowest offset (moved by a
                    // negative offset) up. Its destinations may hold any frame address those
                    // words hold; a word reached through any other register holds none that has
                    // not escaped.
                    let span = match (base_sp, sp, insn.memory_offset()) {
                        (true, Some(sp), Some(off)) => i32::try_from(off)
                            .ok()
                            .map(|off| (sp.saturating_add(off), sp.saturating_add(off + 8))),
                        _ => self.reached_from(insn, base).map(|from| (from, i32::MAX)),
                    };
                    let held = span.and_then(|(from, to)| {
                        self.slots
                            .iter()
                            .filter(|&(&at, _)| at.saturating_add(4) > from && at < to)
                            .filter_map(|(_, held)| held.frame_low())
                            .min()
                    });
                    if insn.is_coprocessor_load() {
                        // Into a floating-point register, which the pass does not follow.
                        if let Some(low) = held {
                            self.escape(low);
                        }
                    } else {
                        let value = held
                            .map_or(Holds::UNKNOWN, |low| Holds::UNKNOWN.meet(Holds::frame(low)));
                        let written = insn.writes();
                        loaded.extend(
                            (0..16u8)
                                .filter(|&r| written.contains(r))
                                .map(|r| (r, value)),
                        );
                    }
                }
            }
        }
        // SP's new offset.
        self.sp = match (sp, writes_sp) {
            (_, false) => sp,
            (None, true) => None,
            (Some(sp), true) => Self::moved(insn, sp),
        };
        match self.sp {
            // The words below SP are free: an interrupt's frame may overwrite them.
            Some(now) => self.forget(|at| at < now),
            None => self.forget(|_| true),
        }
        // A frame address stored in a word an escaped address reaches has escaped too.
        self.close();
        loaded
    }

    /// The lowest frame offset an access through `base` (its base register, [`base_of`]) may
    /// reach, where its address may be worked from a frame address: its base's lowest offset
    /// moved by [`reach`], or anywhere in the frame where its index register may hold one (or
    /// its base is not known).
    fn reached_from(&self, insn: &Insn, base: Option<u8>) -> Option<i32> {
        let Some(base) = base else {
            return Some(i32::MIN);
        };
        let through_base = self.frame(base).map(|low| low.saturating_add(reach(insn)));
        let through_index = index_of(insn)
            .into_iter()
            .find_map(|r| self.frame(r))
            .map(|_| i32::MIN);
        through_base.into_iter().chain(through_index).min()
    }

    /// What a load through SP (offset `sp` from the entry's) reads into which registers, where
    /// it reads whole words at offsets the pass computes: `LDR`, `LDRD`, `POP`, `LDM`.
    fn load_from_frame(&self, insn: &Insn, sp: i32) -> Option<Vec<(u8, Holds)>> {
        // A word kept at the offset; else anything, or a frame address a kept word it overlaps
        // (one an unaligned store kept) holds.
        let word = |at: i32| match self.slots.get(&at) {
            Some(&held) => held,
            None => self
                .slots
                .range(at.saturating_sub(3)..at.saturating_add(4))
                .filter_map(|(_, held)| held.frame_low())
                .min()
                .map_or(Holds::UNKNOWN, |low| Holds::UNKNOWN.meet(Holds::frame(low))),
        };
        match insn.inst.opcode {
            Opcode::LDR | Opcode::LDRD => {
                // `LDRD Rt, Rt2`: Rt from the word at the address, Rt2 from the next.
                let off = self.access(insn)?;
                let count = if insn.inst.opcode == Opcode::LDRD {
                    2
                } else {
                    1
                };
                let regs = insn.registers();
                (regs.len() >= count).then(|| {
                    (0..count)
                        .map(|k| (regs[k], word(sp + off + 4 * k as i32)))
                        .collect()
                })
            }
            Opcode::POP | Opcode::LDM(..) => {
                let list = list_of(insn)?;
                let mut at = sp + reach(insn);
                let mut out = Vec::new();
                for r in (0..16u8).filter(|r| list & 1 << r != 0) {
                    out.push((r, word(at)));
                    at += 4;
                }
                Some(out)
            }
            _ => None,
        }
    }

    /// The offset from SP of a word access through SP (pre-indexed or plain; post-indexed: 0).
    fn access(&self, insn: &Insn) -> Option<i32> {
        match insn.inst.operands.iter().find(|o| {
            matches!(
                o,
                Operand::RegDerefPostindexOffset(..)
                    | Operand::RegDerefPostindexReg(..)
                    | Operand::RegDerefPostindexRegShift(..)
            )
        }) {
            Some(Operand::RegDerefPostindexOffset(..)) => Some(0),
            Some(_) => None,
            None => insn.memory_offset().and_then(|o| i32::try_from(o).ok()),
        }
    }

    /// SP's offset after `insn`, which writes SP (`sp` before it).
    fn moved(insn: &Insn, sp: i32) -> Option<i32> {
        let words = |list: u16| 4 * list.count_ones() as i32;
        match insn.inst.opcode {
            Opcode::PUSH | Opcode::STM(false, true, true, _) => Some(sp - words(list_of(insn)?)),
            Opcode::POP | Opcode::LDM(true, false, true, _) => Some(sp + words(list_of(insn)?)),
            Opcode::ADD | Opcode::SUB
                if insn.registers().iter().all(|&r| r == SP) && insn.memory_base().is_none() =>
            {
                let imm = i32::try_from(insn.immediate()?).ok()?;
                Some(if insn.inst.opcode == Opcode::ADD {
                    sp + imm
                } else {
                    sp - imm
                })
            }
            _ if insn.vpush_words().is_some() => {
                Some(sp - 4 * i32::try_from(insn.vpush_words()?).ok()?)
            }
            _ => insn.inst.operands.iter().find_map(|o| match *o {
                Operand::RegDerefPreindexOffset(_, off, add, true)
                | Operand::RegDerefPostindexOffset(_, off, add, _) => {
                    let off = i32::from(off);
                    Some(if add { sp + off } else { sp - off })
                }
                _ => None,
            }),
        }
    }

    /// A store through SP (offset `sp` from the entry's); `before` the registers before it.
    /// Returns whether each register it stores is now in a word the pass keeps (a whole-word
    /// store at offsets it computes: `STR`, `STRD`, `PUSH`, `STM`).
    fn store_to_frame(&mut self, insn: &Insn, sp: i32, before: &[Holds; 16]) -> bool {
        let opcode = insn.inst.opcode;
        // SP stored is the frame address it holds.
        let value = |r: u8| {
            if r == SP {
                Holds::frame(sp)
            } else {
                before[usize::from(r)]
            }
        };
        let mut words: Vec<(i32, Holds)> = Vec::new();
        match opcode {
            Opcode::PUSH | Opcode::STM(..) => {
                let list = list_of(insn).unwrap_or(0);
                let mut at = sp + reach(insn);
                for r in (0..16u8).filter(|r| list & 1 << r != 0) {
                    words.push((at, value(r)));
                    at += 4;
                }
            }
            Opcode::STR | Opcode::STRD => match (self.access(insn), &insn.registers()[..]) {
                (Some(off), &[rt, ..]) if opcode == Opcode::STR => {
                    words.push((sp + off, value(rt)))
                }
                (Some(off), &[rt, rt2, ..]) => {
                    words.push((sp + off, value(rt)));
                    words.push((sp + off + 4, value(rt2)));
                }
                _ => {
                    self.forget(|_| true);
                    return false;
                }
            },
            _ => {
                match self.access(insn) {
                    // Bytes, halfwords, a floating-point word or two: what they overlap is lost.
                    Some(off) if insn.vpush_words().is_none() => self.clobber(sp + off, 8),
                    // `VPUSH`: below SP, where no word is kept.
                    _ if insn.vpush_words().is_some() => {}
                    _ => self.forget(|_| true),
                }
                return false;
            }
        }
        for (at, held) in words {
            // A conditional store: the word may keep what it held.
            let held = match insn.conditional {
                true => self.slots.remove(&at).unwrap_or(Holds::UNKNOWN).meet(held),
                false => held,
            };
            self.clobber(at, 4);
            self.slots.insert(at, held);
        }
        true
    }

    /// Where `insn` works its destination's value from a frame address (SP, or a register that
    /// may hold one, among the registers its value is worked from: not a load's, whose value
    /// comes from memory, nor a store's): the lowest frame offset the result may point to. Only
    /// a step that cannot take the address below its object keeps it there: an immediate added
    /// or taken away moves it by the immediate, a register added, shifted or not (an element's
    /// offset in the object: a pointer worked from an object's address stays in the object), a
    /// carry added or bits set (`ADC`, `ORR`) and a copy keep it; anything else (a register
    /// taken away, bits cleared, the address itself shifted, a multiply, an extension) may point
    /// anywhere in the frame.
    fn worked_from_frame(&self, insn: &Insn) -> Option<i32> {
        if insn.is_load() || insn.is_store() || insn.writes().contains(SP) {
            return None;
        }
        let mut sources = super::stored::reads(insn);
        // Destinations `reads` counts as read but these only write: an `MRS`'s, a two-operand
        // extension's, count's, reversal's, and the long multiplies' RdHi (the accumulating ones
        // read it).
        let regs = insn.registers();
        let only_written: &[u8] = match insn.inst.opcode {
            Opcode::UMULL | Opcode::SMULL => regs.get(..2).unwrap_or(&[]),
            Opcode::MRS
            | Opcode::UXTB
            | Opcode::UXTH
            | Opcode::SXTB
            | Opcode::SXTH
            | Opcode::CLZ
            | Opcode::RBIT
            | Opcode::REV
            | Opcode::REV16
            | Opcode::REVSH => regs.get(..1).unwrap_or(&[]),
            _ => &[],
        };
        for &r in only_written {
            // Unless it is the source as well (`UXTB r0, r0`).
            if regs.iter().filter(|&&x| x == r).count() == 1 {
                sources &= !(1u16 << r);
            }
        }
        let low = (0..16u8)
            .filter(|r| sources & 1 << r != 0)
            .filter_map(|r| self.frame(r))
            .min()?;
        let imm = insn.immediate().and_then(|v| i32::try_from(v).ok());
        // A frame address shifted (`ADD Rd, Rn, Rm, LSL #3` with Rm the address) is no address.
        let scaled = insn.inst.operands.iter().any(|o| match o {
            Operand::RegShift(shift) => match shift.into_shift() {
                RegShiftStyle::RegImm(s) => {
                    !(s.stype() == ShiftStyle::LSL && s.imm() == 0)
                        && self.frame(s.shiftee().number()).is_some()
                }
                RegShiftStyle::RegReg(s) => {
                    self.frame(s.shiftee().number()).is_some()
                        || self.frame(s.shifter().number()).is_some()
                }
            },
            _ => false,
        });
        Some(match (insn.inst.opcode, imm) {
            _ if scaled => i32::MIN,
            (Opcode::ADD, Some(imm)) => low.saturating_add(imm),
            (Opcode::SUB, Some(imm)) => low.saturating_sub(imm),
            // An index added (shifted or not: an element's offset), a carry, bits set, a copy.
            (Opcode::ADD | Opcode::ADC | Opcode::ORR | Opcode::MOV, _) => low,
            // `MOVS Rd, Rm` decodes as `LSLS Rd, Rm, #0`: a copy.
            (Opcode::LSL, Some(0)) => low,
            _ => i32::MIN,
        })
    }

    /// The base `insn` writes back (`LDR Rt, [Rn], #k`, `STR Rt, [Rn, #k]!`, `LDM Rn!`, but SP,
    /// whose offset [`Self::step_frame`] follows) where it may hold a frame address, and what it
    /// then holds: that address moved (an immediate taken away moves its lowest offset down, one
    /// added keeps it; a register index taken away may reach anywhere in the frame, one added
    /// keeps it).
    fn written_back(&self, insn: &Insn) -> Option<(u8, Holds)> {
        let (base, moved) = insn.inst.operands.iter().find_map(|o| match *o {
            Operand::RegDerefPostindexOffset(rn, k, add, _)
            | Operand::RegDerefPreindexOffset(rn, k, add, true) => {
                let k = i32::from(k);
                Some((rn.number(), Some(if add { k } else { -k })))
            }
            Operand::RegDerefPostindexReg(rn, _, add, _)
            | Operand::RegDerefPreindexReg(rn, _, add, true)
            | Operand::RegDerefPostindexRegShift(rn, _, add, _)
            | Operand::RegDerefPreindexRegShift(rn, _, add, true) => {
                Some((rn.number(), add.then_some(0)))
            }
            // A multiple (a floating-point one too): down by the list where it decrements.
            Operand::RegWBack(rn, true) => Some((rn.number(), Some(reach(insn).min(0)))),
            _ => None,
        })?;
        if base == SP || !insn.writes().contains(base) {
            return None;
        }
        let held = self.regs[usize::from(base)];
        let low = held.frame_low()?;
        let low = moved.map_or(i32::MIN, |k| low.saturating_add(k.min(0)));
        let rest = if held.may & !FRAME != 0 {
            Holds::UNKNOWN
        } else {
            Holds::default()
        };
        Some((base, Holds::frame(low).meet(rest)))
    }

    /// The registers after `insn`: constants as [`crate::waits::step_constants`] follows them, a
    /// mask register an `MRS` saves, a copy (`MOV rD, rM`) what its source held, a register an
    /// outlined helper does not write what it held before the call, a word loaded from the frame
    /// what the store of it held; a conditional write (in an `IT` block) joined with the value
    /// before it.
    pub(super) fn step(&mut self, image: &Image, insn: &Insn) {
        if let Some((body, tail_call)) = outlined_body(image, insn) {
            // A machine-outlined helper is straight-line code on its caller's registers and
            // frame: its instructions, stepped here, are the call's effect (and LR); one that
            // ends in a branch to a function calls it.
            for i in body {
                self.step(image, i);
            }
            if tail_call {
                self.call_escapes();
                for r in [0, 1, 2, 3, 12] {
                    self.regs[r] = Holds::UNKNOWN;
                }
            }
            self.regs[usize::from(LR)] = Holds::UNKNOWN;
            return;
        }
        let mut taken: [Option<u32>; 16] = std::array::from_fn(|r| self.regs[r].constant);
        crate::waits::step_constants(image, insn, &mut taken, Conditional::Taken);
        let [hw1, hw2] = insn.raw;
        // MRS (ARMv7-M ARM B5.2.2): hw1 0xf3ef, hw2 1000 Rd SYSm.
        let saved = if insn.len == 4 && hw1 == 0xf3ef && hw2 & 0xf000 == 0x8000 {
            let kind = match hw2 & 0xff {
                0x10 => Some(Kind::Primask),
                0x11 | 0x12 => Some(Kind::Basepri),
                0x13 => Some(Kind::Faultmask),
                _ => None,
            };
            Some(((hw2 >> 8) as u8 & 0xf, kind))
        } else {
            None
        };
        // An `MRS` of MSP or PSP (SYSm 8, 9) may read SP: a frame address.
        let stack_read = match saved {
            Some((d, None)) if matches!(hw2 & 0xff, 8 | 9) => Some((
                d,
                Holds::UNKNOWN.meet(Holds::frame(self.sp.unwrap_or(i32::MIN))),
            )),
            _ => None,
        };
        let copied = match (insn.inst.opcode, &insn.inst.operands[..2]) {
            (Opcode::MOV, [Operand::Reg(d), Operand::Reg(m)]) => {
                Some((d.number(), self.regs[usize::from(m.number())]))
            }
            _ => None,
        };
        // A call of an outlined helper writes what the helper writes (and LR), no more: what an
        // `MRS` saved in r0-r3 lives through it.
        let written = match (&insn.outlined, insn.inst.opcode) {
            (Some(outlined), Opcode::BL) => Regs(outlined.writes | 1 << 14),
            // A supervisor call's handler may change the registers the exception stacked: r0-r3,
            // r12 and LR.
            (_, Opcode::SVC) => Regs(0b0101_0000_0000_1111),
            _ => insn.writes(),
        };
        let before = self.regs;
        let from_frame = self.worked_from_frame(insn);
        let moved_base = self.written_back(insn);
        let loaded = self.step_frame(insn);
        for r in 0..16u8 {
            if !written.contains(r) {
                continue;
            }
            let i = usize::from(r);
            let value = match (saved, copied, taken[i]) {
                (Some((d, Some(kind))), _, _) if d == r => Holds::saved(kind),
                _ if stack_read.is_some_and(|(d, _)| d == r) => {
                    stack_read.map_or(Holds::UNKNOWN, |(_, held)| held)
                }
                (_, Some((d, held)), _) if d == r => held,
                (_, _, Some(v)) => Holds::constant(v),
                _ => loaded
                    .iter()
                    .find(|&&(d, _)| d == r)
                    .map_or(Holds::UNKNOWN, |&(_, held)| held),
            };
            let value = match moved_base {
                // A base written back: the address it held, moved.
                Some((base, held)) if base == r => held,
                _ => match from_frame {
                    Some(low) => value.meet(Holds::frame(low)),
                    None => value,
                },
            };
            self.regs[i] = if insn.conditional {
                before[i].meet(value)
            } else {
                value
            };
        }
        // SP is reached wherever the function is ([`Known::reached`]).
        self.regs[usize::from(SP)] = Holds::UNKNOWN;
    }
}

/// What the registers may hold at the entry of each block of a function's graph: a forward
/// data-flow pass to its fixed point, across blocks and the copies node splitting made; a lowest
/// frame offset that keeps going down at a block's entry (a frame address stepped down on every
/// pass of a loop) is widened to any offset ([`Known::widen`]), so the pass ends.
pub(super) struct Masks {
    entry: Vec<Known>,
}

impl Masks {
    pub(super) fn new(image: &Image, insns: &[Insn], graph: &Cfg) -> Masks {
        let n = graph.blocks.len();
        let mut entry = vec![Known::unreached(); n];
        if n == 0 {
            return Masks { entry };
        }
        entry[0] = Known::entry();
        let mut work = vec![0usize];
        let mut queued = vec![false; n];
        let mut lowered: BTreeMap<(usize, Place), u32> = BTreeMap::new();
        queued[0] = true;
        while let Some(x) = work.pop() {
            queued[x] = false;
            let block = &graph.blocks[x];
            let mut out = entry[x].clone();
            for insn in &insns[block.first..=block.last] {
                out.step(image, insn);
            }
            for e in &block.succs {
                let old = entry[e.to].clone();
                if entry[e.to].meet(&out) {
                    entry[e.to].widen(&old, |place| {
                        let n = lowered.entry((e.to, place)).or_insert(0);
                        *n += 1;
                        *n
                    });
                    if !queued[e.to] {
                        queued[e.to] = true;
                        work.push(e.to);
                    }
                }
            }
        }
        Masks { entry }
    }

    /// What the registers may hold at the entry of block `b`.
    pub(super) fn entry(&self, b: usize) -> Known {
        self.entry[b].clone()
    }
}

/// The masking effect of `insn` (its encoding: ARMv7-M ARM B5.2.3 `MSR`, B5.2.1 `CPS`); `known`
/// what the registers may hold before it. An `MSR` of PRIMASK or FAULTMASK is a raise when its
/// register may hold a constant with bit 0 set on some path; one of BASEPRI when it may hold a
/// nonzero constant; a restore when it holds, on every path, what an `MRS` of the same register
/// saved or a constant that clears the mask; else unclear. A conditional `MSR` (in an `IT` block)
/// has its effect where it executes: a raise is counted as one ([`region`] declines a section
/// whose restore is conditional).
pub(super) fn effect(insn: &Insn, known: &Known) -> Option<Effect> {
    let [hw1, hw2] = insn.raw;
    if insn.len == 2 && hw1 & 0xffe8 == 0xb660 {
        // CPS: im (bit 4) 1 disables; I (bit 1) is PRIMASK, F (bit 0) FAULTMASK.
        let kind = match hw1 & 0b11 {
            0b10 => Kind::Primask,
            0b01 => Kind::Faultmask,
            0b11 => return Some(Effect::Unclear(Kind::Primask)),
            _ => return None,
        };
        return Some(if hw1 & 0x10 != 0 {
            Effect::Raise(kind, None)
        } else {
            Effect::Restore(kind)
        });
    }
    if insn.len == 4 && hw1 & 0xfff0 == 0xf380 && hw2 & 0xff00 == 0x8800 {
        let rn = (hw1 & 0xf) as u8;
        let may = known.regs[usize::from(rn)].may;
        let (kind, saved, raises, raise_reg) = match hw2 & 0xff {
            0x10 => (Kind::Primask, SAVED_PRIMASK, ODD, None),
            0x11 => (Kind::Basepri, SAVED_BASEPRI, ODD | EVEN, Some(rn)),
            0x12 => return Some(Effect::Raise(Kind::Basepri, Some(rn))),
            0x13 => (Kind::Faultmask, SAVED_FAULTMASK, ODD, None),
            _ => return None,
        };
        // What clears the mask: 0, and for PRIMASK and FAULTMASK (one bit) any even constant.
        let clears = if kind == Kind::Basepri {
            ZERO
        } else {
            ZERO | EVEN
        };
        return Some(if may & raises != 0 {
            Effect::Raise(kind, raise_reg)
        } else if may & !(saved | clears) == 0 {
            Effect::Restore(kind)
        } else {
            Effect::Unclear(kind)
        });
    }
    None
}

/// The part of `graph` a section runs through, as a graph of its own: block 0 from the raise
/// (instruction `k` of block `b`) on, every block a path reaches before its kind's nesting is back
/// where it was (a copy per nesting depth it is reached at), ending at that restore (an exit).
pub(super) fn region(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    masks: &Masks,
    b: usize,
    k: usize,
    kind: Kind,
) -> Result<Cfg, String> {
    // (block, first instruction, depth on entry) → sub-block.
    let mut index: BTreeMap<(usize, usize, u32), usize> = BTreeMap::new();
    let mut blocks: Vec<Block> = Vec::new();
    let mut work = vec![(b, k, 0u32)];
    index.insert((b, k, 0), 0);
    blocks.push(placeholder());
    while let Some((ob, first, depth_in)) = work.pop() {
        let me = index[&(ob, first, depth_in)];
        let block = &graph.blocks[ob];
        let mut depth = depth_in;
        let mut known = masks.entry(ob);
        let mut end = None;
        for (j, insn) in insns
            .iter()
            .enumerate()
            .take(block.last + 1)
            .skip(block.first)
        {
            if j >= first {
                match effect(insn, &known) {
                    Some(Effect::Raise(kd, _)) if kd == kind => depth += 1,
                    // A restore that may not execute: the section may run on past it, to a
                    // restore this part of the graph does not fix.
                    Some(Effect::Restore(kd)) if kd == kind && insn.conditional => {
                        return Err(format!(
                            "restored under a condition (an IT block) at {:#010x}",
                            insn.addr
                        ));
                    }
                    Some(Effect::Restore(kd)) if kd == kind => {
                        depth = depth.saturating_sub(1);
                        if depth == 0 {
                            end = Some(j);
                            break;
                        }
                    }
                    _ => {}
                }
                if depth > MAX_NESTING {
                    return Err(format!(
                        "raises nest deeper than {MAX_NESTING} on a path from the raise"
                    ));
                }
            }
            known.step(image, insn);
        }
        if let Some(j) = end {
            blocks[me] = Block {
                first,
                last: j,
                succs: Vec::new(),
                call: None,
                exit: true,
                copy: block.copy,
            };
            continue;
        }
        if block.exit {
            return Err(format!(
                "not restored before the function returns (at {:#010x})",
                insns[block.last].addr
            ));
        }
        let mut succs = Vec::new();
        for e in &block.succs {
            let key = (e.to, graph.blocks[e.to].first, depth);
            let to = match index.get(&key) {
                Some(&to) => to,
                None => {
                    let to = blocks.len();
                    blocks.push(placeholder());
                    index.insert(key, to);
                    work.push(key);
                    to
                }
            };
            succs.push(Edge { to, taken: e.taken });
        }
        blocks[me] = Block {
            first,
            last: block.last,
            succs,
            call: block.call,
            exit: false,
            copy: block.copy,
        };
    }
    Ok(Cfg { blocks })
}

fn placeholder() -> Block {
    Block {
        first: 0,
        last: 0,
        succs: Vec::new(),
        call: None,
        exit: false,
        copy: false,
    }
}

/// What a forward pass knows of one register at a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Held {
    /// No path reaches it (yet).
    Unreached,
    Constant(u32),
    Unknown,
}

impl Held {
    fn meet(self, other: Held) -> Held {
        match (self, other) {
            (Held::Unreached, x) | (x, Held::Unreached) => x,
            (Held::Constant(a), Held::Constant(b)) if a == b => Held::Constant(a),
            _ => Held::Unknown,
        }
    }
}

/// `held` after `run`: the constants [`crate::waits::step_constants`] follows on every path (a
/// conditional write joined with the value before it), `r` seeded with what it held before.
fn through(image: &Image, run: &[Insn], r: u8, held: Held) -> Held {
    let mut known = [None; 16];
    if let Held::Constant(v) = held {
        known[usize::from(r)] = Some(v);
    }
    let mut written = false;
    for insn in run {
        // A register copied (`MOV rD, rM`) holds what its source held.
        let copied = match (insn.inst.opcode, &insn.inst.operands[..2]) {
            (Opcode::MOV, [Operand::Reg(d), Operand::Reg(m)]) if !insn.conditional => {
                Some((d.number(), known[usize::from(m.number())]))
            }
            _ => None,
        };
        crate::waits::step_constants(image, insn, &mut known, Conditional::Joined);
        if let Some((d, v)) = copied {
            known[usize::from(d)] = v;
        }
        written |= insn.writes().contains(r);
    }
    match (written, known[usize::from(r)]) {
        (false, _) => held,
        (true, Some(v)) => Held::Constant(v),
        (true, None) => Held::Unknown,
    }
}

/// The constant register `r` holds before instruction `k` of block `b` on every path from the
/// function's entry (a forward data-flow pass to its fixed point: a value set before a loop and
/// not written in it is still known in it), `None` when it is not one constant.
pub(super) fn value_before(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    b: usize,
    k: usize,
    r: u8,
) -> Option<u32> {
    let n = graph.blocks.len();
    let mut entry = vec![Held::Unreached; n];
    entry[0] = Held::Unknown;
    let mut work: Vec<usize> = vec![0];
    let mut queued = vec![false; n];
    queued[0] = true;
    while let Some(x) = work.pop() {
        queued[x] = false;
        let block = &graph.blocks[x];
        let out = through(image, &insns[block.first..=block.last], r, entry[x]);
        for e in &block.succs {
            let met = entry[e.to].meet(out);
            if met != entry[e.to] {
                entry[e.to] = met;
                if !queued[e.to] {
                    queued[e.to] = true;
                    work.push(e.to);
                }
            }
        }
    }
    match through(image, &insns[graph.blocks[b].first..k], r, entry[b]) {
        Held::Constant(v) => Some(v),
        _ => None,
    }
}

/// The base register of a memory access: its memory operand's, a load or store multiple's
/// (written back or not; a floating-point one's too), SP for `PUSH` and `POP`.
fn base_of(insn: &Insn) -> Option<u8> {
    if matches!(insn.inst.opcode, Opcode::PUSH | Opcode::POP) {
        return Some(SP);
    }
    insn.memory_base().or_else(|| {
        insn.inst.operands.iter().find_map(|o| match *o {
            Operand::RegWBack(r, _) => Some(r.number()),
            _ => None,
        })
    })
}

/// The index registers of a memory operand (`[Rn, Rm]`, `[Rn, Rm, LSL #k]`, post-indexed too).
fn index_of(insn: &Insn) -> Vec<u8> {
    let mut out = Vec::new();
    for o in &insn.inst.operands {
        match o {
            Operand::RegDerefPreindexReg(_, rm, ..) | Operand::RegDerefPostindexReg(_, rm, ..) => {
                out.push(rm.number())
            }
            Operand::RegDerefPreindexRegShift(_, shift, ..)
            | Operand::RegDerefPostindexRegShift(_, shift, ..) => match shift.into_shift() {
                RegShiftStyle::RegImm(s) => out.push(s.shiftee().number()),
                RegShiftStyle::RegReg(s) => {
                    out.extend([s.shiftee().number(), s.shifter().number()])
                }
            },
            _ => {}
        }
    }
    out
}

/// Where the lowest byte `insn` accesses lies from its base register's value before it, as far
/// as the instruction says: a negative immediate offset, a list stored or loaded below the base
/// (`STMDB`, `PUSH`, `VPUSH`, `VSTMDB`); 0 where it accesses from the base up (a positive offset
/// is taken as 0, a conservative bound); anywhere where a register offset may be negative.
fn reach(insn: &Insn) -> i32 {
    let opcode = insn.inst.opcode;
    let ops = &insn.inst.operands;
    if let Some(off) = insn.memory_offset() {
        return i32::try_from(off.min(0)).unwrap_or(i32::MIN);
    }
    if ops.iter().any(|o| {
        matches!(
            o,
            Operand::RegDerefPostindexOffset(..)
                | Operand::RegDerefPostindexReg(..)
                | Operand::RegDerefPostindexRegShift(..)
        )
    }) {
        // Post-indexed: at the base.
        return 0;
    }
    let words = |list: Option<u16>| 4 * list.unwrap_or(0xffff).count_ones() as i32;
    match opcode {
        Opcode::STM(true, ..) | Opcode::LDM(true, ..) | Opcode::POP => 0,
        Opcode::STM(false, ..) | Opcode::LDM(false, ..) | Opcode::PUSH => -words(list_of(insn)),
        // VSTM/VLDM (ARMv7-M ARM A7.7.250): P (hw1 bit 8) set decrements before, by imm8 words.
        _ if insn.is_coprocessor_load() || insn.is_coprocessor_store() => {
            if insn.raw[0] & 0x100 != 0 {
                -4 * i32::from(insn.raw[1] & 0xff)
            } else {
                0
            }
        }
        _ => i32::MIN,
    }
}

/// The core registers `insn` copies where the pass does not follow them: a floating-point
/// register (`VMOV Sn, Rt`, `VMOV Sm, Sm1, Rt, Rt2`, `VMSR`: `MCR`/`MCRR`, Rt in hw2 15:12 and
/// Rt2 in hw1 3:0), a special register other than a mask (`MSR`: ARMv7-M ARM B5.2.3, Rn in hw1
/// 3:0), and the parameter block of a semihosting call (r1), which the debugger reads and writes.
fn moved_out(insn: &Insn) -> Vec<u8> {
    let [hw1, hw2] = insn.raw;
    match insn.inst.opcode {
        Opcode::MCR(..) => vec![(hw2 >> 12) as u8],
        Opcode::MCRR(..) => vec![(hw2 >> 12) as u8, (hw1 & 0xf) as u8],
        _ if special_register_written(insn).is_some_and(|sysm| !(0x10..=0x13).contains(&sysm)) => {
            vec![(hw1 & 0xf) as u8]
        }
        _ if insn.is_semihosting() => vec![1],
        _ => Vec::new(),
    }
}

/// The special register (SYSm) an `MSR` writes.
fn special_register_written(insn: &Insn) -> Option<u16> {
    let [hw1, hw2] = insn.raw;
    (insn.len == 4 && hw1 & 0xfff0 == 0xf380 && hw2 & 0xf300 == 0x8000).then_some(hw2 & 0xff)
}

/// Whether `insn` is an `MSR` that may move SP: of MSP (8), PSP (9) or CONTROL (0x14, whose
/// SPSEL picks which of them SP is).
fn writes_stack_pointer(insn: &Insn) -> bool {
    special_register_written(insn).is_some_and(|sysm| matches!(sysm, 8 | 9 | 0x14))
}

/// The registers a `PUSH`, `POP`, `LDM` or `STM` transfers (a one-register `PUSH`/`POP` too).
fn list_of(insn: &Insn) -> Option<u16> {
    insn.register_list().or_else(|| match insn.inst.opcode {
        Opcode::PUSH | Opcode::POP => insn.registers().first().map(|&r| 1u16 << r),
        _ => None,
    })
}

/// The instructions of the machine-outlined helper an unconditional `BL` calls, but its last,
/// where they run straight to it, and whether that last is a branch to a function (a call) rather
/// than a return.
fn outlined_body<'i>(image: &'i Image, insn: &Insn) -> Option<(&'i [Insn], bool)> {
    if insn.outlined.is_none() || insn.conditional || insn.inst.opcode != Opcode::BL {
        return None;
    }
    let Flow::Call(target) = insn.flow() else {
        return None;
    };
    let helper = image.function_at(target)?;
    let insns = helper.instructions().ok()?;
    let (last, body) = insns.split_last()?;
    let tail_call = match last.flow() {
        Flow::Return => false,
        Flow::Branch(t) if !last.conditional && image.function_at(t).is_some() => {
            !helper.contains(t)
        }
        _ => return None,
    };
    body.iter()
        .all(|i| i.flow() == Flow::Next)
        .then_some((body, tail_call))
}
