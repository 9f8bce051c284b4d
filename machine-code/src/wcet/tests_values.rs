//! Known answers for the register values followed across blocks ([`super::values`]): a load whose
//! base was set in another block is charged its memory's latency (docs/analysis.md, "The cycle
//! model"), worked from the Cortex-M3 TRM's table (ARM DDI 0337, table 18-1: data processing 1,
//! `LDR` 2, `PUSH`/`POP` 1 + N, a taken branch or a call 1 + P with P = 3) and the F103's memory
//! system (a data read from flash w more at w wait states, a taken branch w more; an AHB access 1
//! more, an APB1 access 5 more; a load of an unknown address the worse of w and 5).
use super::*;
use crate::testelf::{elf, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };
const F103_2WS: Chip = Chip::Stm32f103 { wait_states: 2 };

fn image(code: &[u16], symbols: &[Sym]) -> Image {
    Image::parse(&elf(&thumb(code), symbols)).expect("the test image parses")
}

fn figures(image: &Image, f: &str, chip: Chip) -> (u64, u64, Option<String>) {
    let b = bound_function(image, f, chip, &BoundsFile::default()).expect("analysed");
    (b.cycles, b.instructions, b.declined)
}

#[test]
fn an_address_built_before_a_loop_is_known_in_it() {
    let img = image(
        &[
            0x4904, // 0x00 ldr r1, [pc, #16]: RCC's address (0x4002_1000, AHB) from flash: 2 + w
            0xa405, // 0x02 adr r4, 0x18: a table in flash: 1
            0x2300, // 0x04 movs r3, #0: 1
            0x680a, // 0x06 ldr r2, [r1]: RCC, AHB: 2 + 1         (the loop: 4 passes)
            0x6860, // 0x08 ldr r0, [r4, #4]: the table, flash: 2 + w
            0x3301, // 0x0a adds r3, #1: 1
            0x2b04, // 0x0c cmp r3, #4: 1
            0xd1fa, // 0x0e bne 0x06: 1, taken + P + w
            0x4770, // 0x10 bx lr: 1 + P + w
            0xbf00, // 0x12 (padding)
            0x1000, 0x4002, // 0x14 .word 0x40021000
            0x0001, 0x0000, 0x0002, 0x0000, // 0x18 the table
        ],
        &[Sym::function("across", 0, 0x20), Sym::data(0x14)],
    );
    // 2 wait states (every block costs more than its flash lines at 3 cycles a line): before the
    // loop 4 + 1 + 1 = 6; a pass 3 + 4 + 1 + 1 + 1 = 10, a branch back 5 more, 4 passes 3 × 15 +
    // 10 = 55; bx lr 6: 67 cycles. With the two loads charged as unknown (2 + 5 each) a pass would
    // cost 7 more: 95.
    assert_eq!(figures(&img, "across", F103_2WS), (67, 3 + 4 * 5 + 1, None));
}

/// Two ways into one load: the first brings a RAM address, the second `second`'s.
fn two_ways(second: u32) -> Image {
    let [low, high] = [second as u16, (second >> 16) as u16];
    image(
        &[
            0xb108, // 0x00 cbz r0, 0x06: 1, taken + P
            0x4902, // 0x02 ldr r1, [pc, #8]: 0x2000_0100 (RAM): 2
            0xe000, // 0x04 b 0x08: 1 + P
            0x4902, // 0x06 ldr r1, [pc, #8]: `second`: 2
            0x680a, // 0x08 ldr r2, [r1]: the worse of the two
            0x4770, // 0x0a bx lr: 1 + P
            0x0100, 0x2000, // 0x0c .word 0x20000100
            low, high, // 0x10 .word second
        ],
        &[Sym::function("join", 0, 0x14), Sym::data(0x0c)],
    )
}

#[test]
fn two_ways_that_bring_different_regions_are_charged_the_worse() {
    // RAM on one way, TIM2 (0x4000_0000, APB1) on the other: the load is charged APB1, 2 + 5, on
    // both ways. The way through the RAM address is the longer: 1 + 2 + 4 + 7 + 4 = 18 cycles, 5
    // instructions (the other 4 + 2 + 7 + 4 = 17).
    assert_eq!(
        figures(&two_ways(0x4000_0000), "join", F103_0WS),
        (18, 5, None)
    );
    // Two RAM addresses: the load is RAM's on both ways, 2: 1 + 2 + 4 + 2 + 4 = 13.
    assert_eq!(
        figures(&two_ways(0x2000_0200), "join", F103_0WS),
        (13, 5, None)
    );
}

#[test]
fn a_call_leaves_its_argument_registers_unknown_and_keeps_the_callee_saved() {
    let img = image(
        &[
            0xb510, // 0x00 push {r4, lr}: 1 + 2
            0x4804, // 0x02 ldr r0, [pc, #16]: 0x2000_0100 (RAM): 2
            0x4604, // 0x04 mov r4, r0: 1
            0xf000, 0xf803, // 0x06 bl 0x10: 1 + P
            0x6801, // 0x0a ldr r1, [r0]: r0 is the callee's now, unknown: 2 + 5
            0x6822, // 0x0c ldr r2, [r4]: r4 the callee keeps (AAPCS), RAM: 2
            0xbd10, // 0x0e pop {r4, pc}: 1 + 2 + P
            0x2000, // 0x10 callee: movs r0, #0: 1
            0x4770, // 0x12 bx lr: 1 + P
            0x0100, 0x2000, // 0x14 .word 0x20000100
        ],
        &[
            Sym::function("caller", 0, 0x10),
            Sym::function("callee", 0x10, 0x08),
            Sym::data(0x14),
        ],
    );
    // 3 + 2 + 1 + 4, the callee 1 + 4, then 7 + 2 + 6: 30 cycles; 4 + 2 + 3 instructions.
    assert_eq!(figures(&img, "caller", F103_0WS), (30, 9, None));
}

#[test]
fn a_register_a_loop_changes_is_charged_at_every_value_it_takes() {
    let img = image(
        &[
            0x4903, // 0x00 ldr r1, [pc, #12]: 0x2000_0100 (RAM): 2
            0x2300, // 0x02 movs r3, #0: 1
            0x680a, // 0x04 ldr r2, [r1]: RAM on the first pass, APB1 after: 2 + 5   (3 passes)
            0x4903, // 0x06 ldr r1, [pc, #12]: 0x4000_0000 (TIM2, APB1): 2
            0x3301, // 0x08 adds r3, #1: 1
            0x2b03, // 0x0a cmp r3, #3: 1
            0xd1fa, // 0x0c bne 0x04: 1, taken + P
            0x4770, // 0x0e bx lr: 1 + P
            0x0100, 0x2000, // 0x10 .word 0x20000100
            0x0000, 0x4000, // 0x14 .word 0x40000000
        ],
        &[Sym::function("changes", 0, 0x18), Sym::data(0x10)],
    );
    // 3 before; a pass 7 + 2 + 1 + 1 + 1 = 12, 3 passes 2 × 15 + 12 = 42; bx lr 4: 49 cycles. The
    // value before the loop alone (RAM) would give 34.
    assert_eq!(
        figures(&img, "changes", F103_0WS),
        (49, 2 + 3 * 5 + 1, None)
    );
}

#[test]
fn a_conditional_write_joins_the_value_before_it() {
    let img = image(
        &[
            0x4902, // 0x00 ldr r1, [pc, #8]: 0x4000_0000 (TIM2, APB1): 2
            0x2800, // 0x02 cmp r0, #0: 1
            0xbf08, // 0x04 it eq: 1
            0x4902, // 0x06 ldreq r1, [pc, #8]: 0x2000_0100 (RAM), only when r0 is 0: 2
            0x680a, // 0x08 ldr r2, [r1]: APB1 or RAM: 2 + 5
            0x4770, // 0x0a bx lr: 1 + P
            0x0000, 0x4000, // 0x0c .word 0x40000000
            0x0100, 0x2000, // 0x10 .word 0x20000100
        ],
        &[Sym::function("maybe", 0, 0x14), Sym::data(0x0c)],
    );
    // 2 + 1 + 1 + 2 + 7 + 4 = 17 cycles, 6 instructions (the RAM address taken as written on every
    // way would give 12).
    assert_eq!(figures(&img, "maybe", F103_0WS), (17, 6, None));
}

/// A caller that passes `address` in r0 to a callee that loads through it.
fn passes(address: u32) -> Image {
    let [low, high] = [address as u16, (address >> 16) as u16];
    image(
        &[
            0xb580, // 0x00 push {r7, lr}: 1 + 2
            0x4802, // 0x02 ldr r0, [pc, #8]: `address`: 2
            0xf000, 0xf804, // 0x04 bl 0x10: 1 + P
            0xbd80, // 0x08 pop {r7, pc}: 1 + 2 + P
            0xbf00, // 0x0a (padding)
            low, high,   // 0x0c .word address
            0x6841, // 0x10 callee: ldr r1, [r0, #4]: what the call passed
            0x4770, // 0x12 bx lr: 1 + P
        ],
        &[
            Sym::function("caller", 0, 0x10),
            Sym::data(0x0c),
            Sym::code(0x10),
            Sym::function("callee", 0x10, 4),
        ],
    )
}

#[test]
fn a_callee_is_charged_for_what_its_call_passes() {
    // Alone, the callee's load is of an unknown address: 2 + 5, and 4: 11 cycles.
    assert_eq!(
        figures(&passes(0x2000_0100), "callee", F103_0WS),
        (11, 2, None)
    );
    // Called with a RAM address in r0: the load is RAM's, 2. 3 + 2 + 4, the callee 2 + 4, 6: 21.
    assert_eq!(
        figures(&passes(0x2000_0100), "caller", F103_0WS),
        (21, 6, None)
    );
    // With TIM2's (APB1): 2 + 5 again, 26.
    assert_eq!(
        figures(&passes(0x4000_0000), "caller", F103_0WS),
        (26, 6, None)
    );
}

/// A store through a base and an index register, both constants (`index` a two's complement offset).
fn indexed(index: u32) -> Image {
    let [low, high] = [index as u16, (index >> 16) as u16];
    image(
        &[
            0x4801, // 0x00 ldr r0, [pc, #4]: `index`: 2
            0x4a02, // 0x02 ldr r2, [pc, #8]: 0x4001_0010 (APB2 on the F103): 2
            0x5011, // 0x04 str r1, [r2, r0]: at r2 + r0
            0x4770, // 0x06 bx lr: 1 + P
            low, high, // 0x08 .word index
            0x0010, 0x4001, // 0x0c .word 0x40010010
        ],
        &[Sym::function("indexed", 0, 0x10), Sym::data(0x08)],
    )
}

#[test]
fn a_known_index_register_moves_the_address() {
    // 0x4001_0010 + 0x10: APB2, 2 + 3: 2 + 2 + 5 + 4 = 13 cycles.
    assert_eq!(figures(&indexed(0x10), "indexed", F103_0WS), (13, 4, None));
    // 0x4001_0010 − 0x800 (0xffff_f800 added modulo 2³², as LLVM folds two constants): 0x4000_f810,
    // APB1, 2 + 5: 15 (the base's region alone would say APB2, 13).
    assert_eq!(
        figures(&indexed(0xffff_f800), "indexed", F103_0WS),
        (15, 4, None)
    );
}

#[test]
fn an_unknown_index_keeps_the_base_region_only_where_the_base_is_an_address() {
    // A RAM address in the base, the index unknown (r0, an argument): an index into the object
    // the base addresses, RAM, 2: 2 + 2 + 4 = 8 cycles.
    let img = image(
        &[
            0x4a01, // 0x00 ldr r2, [pc, #4]: 0x2000_0100 (RAM): 2
            0x5811, // 0x02 ldr r1, [r2, r0]: 2
            0x4770, // 0x04 bx lr: 1 + P
            0xbf00, // 0x06 (padding)
            0x0100, 0x2000, // 0x08 .word 0x20000100
        ],
        &[Sym::function("into_ram", 0, 0x0c), Sym::data(0x08)],
    );
    assert_eq!(figures(&img, "into_ram", F103_0WS), (8, 3, None));
    // A small constant in the base (an offset; the pointer is the index): unknown, 2 + 5: 1 + 7 + 4.
    let img = image(
        &[
            0x2210, // 0x00 movs r2, #16: 1
            0x5811, // 0x02 ldr r1, [r2, r0]
            0x4770, // 0x04 bx lr: 1 + P
        ],
        &[Sym::function("offset_base", 0, 6)],
    );
    assert_eq!(figures(&img, "offset_base", F103_0WS), (12, 3, None));
}

/// `op` (at 0x02) through r1, loaded with `address` from flash.
fn through_address(address: u32, op: u16) -> Image {
    let [low, high] = [address as u16, (address >> 16) as u16];
    image(
        &[
            0x4901, // 0x00 ldr r1, [pc, #4]: `address`: 2
            op,     // 0x02 through r1
            0x4770, // 0x04 bx lr: 1 + P
            0xbf00, // 0x06 (padding)
            low, high, // 0x08 .word address
        ],
        &[Sym::function("through", 0, 0x0c), Sym::data(0x08)],
    )
}

#[test]
fn a_bit_band_alias_is_charged_on_the_bus_of_its_bit() {
    // 0x4201_8400 is bit 0 of byte 0x4000_0c20 (0x4000_0000 + 0x1_8400 / 32): TIM5 on APB1. A load
    // of it is one APB1 transfer, 2 + 5; a store a read-modify-write, two APB1 transfers and a
    // cycle between, 2 + 5 + 1 + 5. ldr 2, bx lr 4: 13 and 19 cycles (as AHB, 1 more: 9).
    let str_r0 = 0x6008; // str r0, [r1]
    let ldr_r2 = 0x680a; // ldr r2, [r1]
    assert_eq!(
        figures(&through_address(0x4201_8400, ldr_r2), "through", F103_0WS),
        (13, 3, None)
    );
    assert_eq!(
        figures(&through_address(0x4201_8400, str_r0), "through", F103_0WS),
        (19, 3, None)
    );
    // The SRAM alias: RAM's bit, a store two transfers without wait and the cycle between: 2 + 1.
    assert_eq!(
        figures(&through_address(0x2200_0100, str_r0), "through", F103_0WS),
        (9, 3, None)
    );
    // The plain register: one APB1 store, 2 + 5.
    assert_eq!(
        figures(&through_address(0x4000_0c20, str_r0), "through", F103_0WS),
        (13, 3, None)
    );
}

/// The 32-bit `op` (at 0x02) through r1, loaded with `address` from flash.
fn wide_through_address(address: u32, op: [u16; 2]) -> Image {
    let [low, high] = [address as u16, (address >> 16) as u16];
    image(
        &[
            0x4901, // 0x00 ldr r1, [pc, #4]: `address`: 2
            op[0], op[1],  // 0x02 through r1
            0x4770, // 0x06 bx lr: 1 + P
            low, high, // 0x08 .word address
        ],
        &[Sym::function("through", 0, 0x0c), Sym::data(0x08)],
    )
}

#[test]
fn a_doubleword_reaches_its_second_word() {
    // ldrd r0, r2, [r1]: two words, at the base and 4 above it (TRM: 1 + N = 3 on the core).
    let ldrd = [0xe9d1, 0x0200];
    // In RAM: ldr 2, ldrd 3, bx lr 4: 9 cycles.
    assert_eq!(
        figures(
            &wide_through_address(0x2000_0100, ldrd),
            "through",
            F103_0WS
        ),
        (9, 3, None)
    );
    // From RAM's last word: the second word is TIM2's (0x4000_0000, APB1), and each word is
    // charged the worse, 5 more each: 19 (the first word alone would be RAM's: 9).
    assert_eq!(
        figures(
            &wide_through_address(0x3fff_fffc, ldrd),
            "through",
            F103_0WS
        ),
        (19, 3, None)
    );
}

#[test]
fn a_floating_point_list_is_charged_per_word_over_its_span() {
    const F405_0WS: Chip = Chip::Stm32f405 { wait_states: 0 };
    // vldmia r1, {s0-s3}: 4 words from TIM2 (APB1, on the F405 2 × 4 + 1 = 9 more each), 1 + 4
    // on the core: ldr 2, vldmia 5 + 36, bx lr 4: 47 cycles (one access charged: 20).
    assert_eq!(
        figures(
            &wide_through_address(0x4000_0000, [0xec91, 0x0a04]),
            "through",
            F405_0WS
        ),
        (47, 3, None)
    );
    // vldmdb r1!, {s0-s1} from 0x4001_0004 (APB2's start + 4): the words at 0x4000_fffc (APB1)
    // and 0x4001_0000 (APB2), below the base: 2 × 9 more, 1 + 2 on the core: 2 + 21 + 4 = 27
    // (charged as APB2's base, once: 14).
    assert_eq!(
        figures(
            &wide_through_address(0x4001_0004, [0xed31, 0x0a02]),
            "through",
            F405_0WS
        ),
        (27, 3, None)
    );
}

#[test]
fn an_unknown_index_from_a_bus_start_may_reach_the_bus_below() {
    let img = image(
        &[
            0x4902, // 0x00 ldr r1, [pc, #8]: 0x4001_0000 (APB2's start on the F103): 2
            0x681a, // 0x02 ldr r2, [r3]: an index the code does not fix: 2 + 5 (unknown: APB1)
            0x5888, // 0x04 ldr r0, [r1, r2]: 0x4001_0000 + r2 may be APB1's (r2 = -0x800): 2 + 5
            0x4770, // 0x06 bx lr: 1 + P
            0xbf00, 0xbf00, // 0x08 (padding)
            0x0000, 0x4001, // 0x0c .word 0x40010000
        ],
        &[Sym::function("folded", 0, 0x10), Sym::data(0x0c)],
    );
    // 2 + 7 + 7 + 4 = 20 cycles (charged as APB2's, 2 + 3: 18).
    assert_eq!(figures(&img, "folded", F103_0WS), (20, 4, None));
}
