//! Known answers for a saved mask followed through the function's frame ([`super::masking`]): an
//! `MRS` result spilled to a stack word and loaded back before the `MSR` that restores it (RTIC's
//! lock with a call inside, as LightRing's dispatcher compiles it), and the writes that may
//! overwrite the word in between (docs/analysis.md, "Critical sections"). Cycles from the
//! Cortex-M3 TRM's table (ARM DDI 0337, table 18-1: data processing 1, `LDR` 2, `STR` 2, `LDRD` 3,
//! `MSR` 2, `BL` and a return 1 + P with P = 3) at 0 wait states, the stack in RAM.
use super::*;
use crate::testelf::{elf, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// Where [`lock`]'s code inside the section starts, `prelude` halfwords after its frame is made.
fn inside(prelude: &[u16]) -> u32 {
    0x14 + 2 * prelude.len() as u32
}

/// `callee` at 0x00 (`bx lr`), then `lock` at 0x04: a 16-byte frame (`push {r4, lr}; sub sp,
/// #16`, so SP is 24 below the entry's), `prelude`, the saved BASEPRI spilled to `[sp, #4]`, the
/// raise to 0xb0, `between`, the reload `reload` (an `LDR r0, [sp, #imm]`) and the restore `MSR
/// BASEPRI, r0`.
fn lock(prelude: &[u16], between: &[u16], reload: u16) -> Image {
    let mut code = vec![
        0x4770, // 0x00 bx lr (callee)
        0xbf00, // 0x02 nop
        0xb510, // 0x04 push {r4, lr}
        0xb084, // 0x06 sub sp, #16
    ];
    code.extend_from_slice(prelude);
    code.extend_from_slice(&[
        0xf3ef, 0x8011, // mrs r0, BASEPRI
        0x9001, // str r0, [sp, #4]: the spill
        0x20b0, // movs r0, #0xb0
        0xf380, 0x8812, // msr BASEPRI_MAX, r0: the raise
    ]);
    assert_eq!(2 * code.len() as u32, inside(prelude));
    code.extend_from_slice(between);
    code.extend_from_slice(&[
        reload, 0xf380, 0x8811, // msr BASEPRI, r0: the restore, if r0 holds the saved mask
        0xb004, // add sp, #16
        0xbd10, // pop {r4, pc}
    ]);
    let end = 2 * code.len() as u64;
    image(
        &code,
        &[
            Sym::function("callee", 0, 4),
            Sym::function("lock", 4, end - 4),
        ],
    )
}

fn image(code: &[u16], symbols: &[Sym]) -> Image {
    Image::parse(&elf(&thumb(code), symbols)).expect("the test image parses")
}

/// `BL` from `at` back to `target` (the encoding T1 with S = 1, J1 = J2 = 1: an offset within
/// 4 KiB below).
fn bl_back(at: u32, target: u32) -> [u16; 2] {
    let offset = i64::from(target) - i64::from(at + 4);
    assert!((-4096..0).contains(&offset));
    [0xf7ff, 0xf800 | ((offset >> 1) & 0x7ff) as u16]
}

/// The ceilings `lock` has, with their cycles and instructions, or why its list is incomplete.
fn found(img: &Image) -> Result<Vec<(Ceiling, u64, u64)>, String> {
    let task = Task {
        name: "lock".to_string(),
        entry: TaskEntry::Symbol("lock".to_string()),
        handler: true,
    };
    let found = task_sections(img, &[task], F103_0WS, &BoundsFile::default()).remove(0);
    if let Some(reason) = found.incomplete {
        return Err(reason);
    }
    Ok(found
        .ceilings
        .iter()
        .map(|c| (c.ceiling, c.cycles, c.instructions))
        .collect())
}

const PRIORITY_5: Ceiling = Ceiling::Basepri {
    hardware: 0xb0,
    priority: 5,
};

/// `ldr r0, [sp, #4]`: the spilled word.
const RELOAD: u16 = 0x9801;

/// The list is incomplete, naming the restore (it is the `MSR` after `between`).
fn assert_unclear(img: &Image, between: &[u16]) {
    let restore = inside(&[]) + 2 * between.len() as u32 + 2;
    let reason = found(img).expect_err("the restore's value is not the saved mask");
    assert!(
        reason.contains(&format!("the Basepri write at {restore:#010x}")),
        "{reason}"
    );
}

#[test]
fn a_register_reloaded_by_a_pair_load_holds_what_the_words_held() {
    // A register that held a frame address loaded over by `LDRD` holds what the two words held
    // (here words the function never wrote), not the address: a store through a value worked from
    // it cannot reach the frame, and the spilled mask survives it. (Before, `LDRD`'s second
    // register kept the address it held, a difference of the two made a pointer that might be
    // anywhere in the frame, and the store through it lost the spill: the pattern that made
    // LightRing's UART5 list incomplete.)
    let between = [
        0xaa02, // add r2, sp, #8: 1
        0xe9dd, 0x1202, // ldrd r1, r2, [sp, #8]: 3
        0x1a53, // subs r3, r2, r1: 1
        0x601c, // str r4, [r3]: 2, and 5 more for an address that may be APB1's
    ];
    // msr 2 + 1 + 3 + 1 + 7 + ldr 2 + msr 2 = 18 cycles, 7 instructions.
    assert_eq!(
        found(&lock(&[], &between, RELOAD)),
        Ok(vec![(PRIORITY_5, 18, 7)])
    );
    // Without the pair load r2 still holds a frame address (the spill's own), the difference
    // may point anywhere in the frame, and the store through it may overwrite the spill.
    let between = [
        0xaa01, // add r2, sp, #4
        0xbf00, 0xbf00, // nop; nop
        0x1a53, // subs r3, r2, r1: a frame address moved down by an unknown amount
        0x601c, // str r4, [r3]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

#[test]
fn an_mrs_result_is_the_saved_mask_whatever_its_register_held() {
    // r0 holds a frame address before the MRS overwrites it: the saved value is the mask alone.
    let img = lock(&[0xa802], &[0xbf00], RELOAD); // add r0, sp, #8 before the mrs
                                                  // msr 2 + nop 1 + ldr 2 + msr 2 = 7 cycles, 4 instructions.
    assert_eq!(found(&img), Ok(vec![(PRIORITY_5, 7, 4)]));
}

#[test]
fn a_store_through_a_pointer_that_may_be_the_frames_loses_the_spill() {
    // The spill's address published through r2, a pointer read back from memory, a store
    // through it: it may be the spill's word.
    let between = [
        0xa901, // add r1, sp, #4
        0x6011, // str r1, [r2]: the address escapes
        0x6813, // ldr r3, [r2]: an unknown pointer
        0x601c, // str r4, [r3]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // Without the publication no pointer the code did not work from SP can reach the frame: the
    // store through the unknown pointer leaves the spill. msr 2 + add 1 + nop 1 + ldr 2 + 5 (an
    // unknown address) + str 2 + 5 + ldr 2 + msr 2 = 22 cycles, 7 instructions.
    let between = [0xa901, 0xbf00, 0x6813, 0x601c];
    assert_eq!(
        found(&lock(&[], &between, RELOAD)),
        Ok(vec![(PRIORITY_5, 22, 7)])
    );
}

#[test]
fn a_call_given_the_spills_address_loses_it() {
    let at = inside(&[]);
    // In r0.
    let call = bl_back(at + 2, 0);
    let between = [0xa801, call[0], call[1]]; // add r0, sp, #4; bl callee
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // As a stack argument: the word at SP holds it when the call is made, no register does.
    // (Before, only r0-r3 were read for the callee's pointers.)
    let call = bl_back(at + 6, 0);
    let between = [
        0xa901, // add r1, sp, #4
        0x9100, // str r1, [sp, #0]
        0x2100, // movs r1, #0
        call[0], call[1], // bl callee
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // Given the address of the word above the spill, the callee may write from there up only:
    // msr 2 + add 1 + bl 4 + bx 4 + ldr 2 + msr 2 = 15 cycles, 6 instructions.
    let call = bl_back(at + 2, 0);
    let between = [0xa802, call[0], call[1]]; // add r0, sp, #8; bl callee
    assert_eq!(
        found(&lock(&[], &between, RELOAD)),
        Ok(vec![(PRIORITY_5, 15, 6)])
    );
}

#[test]
fn a_supervisor_call_given_the_spills_address_loses_it() {
    // `add r0, sp, #4; svc #0`: the handler, as a callee, may write through r0.
    let between = [0xa801, 0xdf00];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // It may change the stacked r0 too: the saved mask reloaded into r0 before it is no longer
    // the saved mask after it.
    let between = [0x9801, 0xdf00, 0x4601]; // ldr r0, [sp, #4]; svc #0; mov r1, r0
    assert_unclear(&lock(&[], &between, 0x4608), &between); // mov r0, r1
}

#[test]
fn a_reload_from_another_word_is_no_restore() {
    // ldr r0, [sp, #8]: a word the function never wrote.
    let between = [0xbf00];
    assert_unclear(&lock(&[], &between, 0x9802), &between);
    // ldr r0, [sp, #0] after a store of another value there.
    let between = [0x9100]; // str r1, [sp, #0]
    assert_unclear(&lock(&[], &between, 0x9800), &between);
}

#[test]
fn a_base_written_back_stays_a_frame_address() {
    // r2 walks the frame from SP (`LDR r3, [r2], #4`): it then points at the spill's word, and
    // the store through it overwrites the saved mask. (Before, the written-back base was taken
    // for an unknown value, not the frame's, and the restore was believed.)
    let between = [
        0xaa00, // add r2, sp, #0
        0xf852, 0x3b04, // ldr r3, [r2], #4
        0x6011, // str r1, [r2]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

#[test]
fn a_base_written_back_below_stays_a_frame_address_below() {
    // `vstmdb r2!, {s0}` moves r2 a word down (to [sp, #8]), and the store 4 below it is the
    // spill's word. (Before, a floating-point store multiple's written-back base was taken to move
    // up.)
    let between = [
        0xaa03, // add r2, sp, #12
        0xed22, 0x0a01, // vstmdb r2!, {s0}
        0xf842, 0x1c04, // str.w r1, [r2, #-4]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

#[test]
fn a_spill_overwritten_on_one_path_is_lost_where_the_paths_join() {
    let between = [
        0xb101, // cbz r1, to the nop: over the store
        0x9201, // str r2, [sp, #4]: the spill overwritten where r1 is not 0
        0xbf00, // nop (the join)
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // The saved mask copied to another word on one path only: on the other that word holds
    // whatever it held before the function ran.
    let between = [
        0x9b01, // ldr r3, [sp, #4]: the saved mask
        0xb101, // cbz r1, to the nop
        0x9302, // str r3, [sp, #8]: the copy, where r1 is not 0
        0xbf00, // nop (the join)
    ];
    assert_unclear(&lock(&[], &between, 0x9802), &between); // ldr r0, [sp, #8]
                                                            // The copy made on both paths is the saved mask at the join. The most cycles where the cbz
                                                            // is taken (1 + P = 4): msr 2 + ldr 2 + 4 + str 2 + ldr 2 + msr 2 = 14; the most
                                                            // instructions where it is not: 7.
    let between = [
        0x9b01, // ldr r3, [sp, #4]: the saved mask
        0xb101, // cbz r1, to the second store
        0x9302, // str r3, [sp, #8]: where r1 is not 0
        0x9302, // str r3, [sp, #8]: on both paths
    ];
    assert_eq!(
        found(&lock(&[], &between, 0x9802)),
        Ok(vec![(PRIORITY_5, 14, 7)])
    );
}

#[test]
fn a_pointer_stepped_down_a_loop_reaches_the_spill_and_the_pass_ends() {
    // r2 starts above the spill and goes down a word per pass: its lowest offset keeps going down
    // at the loop's head, is widened to the frame's bottom after a few passes (before, the pass
    // took one round per step, 2^29 of them), and the store through it may be the spill's word.
    let between = [
        0xaa03, // add r2, sp, #12
        0x3a04, // subs r2, #4 (the loop)
        0x6011, // str r1, [r2]
        0x3b01, // subs r3, #1
        0xd1fb, // bne the loop
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

/// The list is incomplete, naming the restore, for [`lock`] with this `prelude` and `between`.
fn assert_unclear_after(img: &Image, prelude: &[u16], between: &[u16]) {
    let restore = inside(prelude) + 2 * between.len() as u32 + 2;
    let reason = found(img).expect_err("the restore's value is not the saved mask");
    assert!(
        reason.contains(&format!("the Basepri write at {restore:#010x}")),
        "{reason}"
    );
}

/// Whether [`lock`] with this `prelude`, `between` and `reload` makes the list incomplete, naming
/// the restore.
fn names_the_restore(prelude: &[u16], between: &[u16], reload: u16) -> bool {
    let restore = inside(prelude) + 2 * between.len() as u32 + 2;
    found(&lock(prelude, between, reload))
        .is_err_and(|reason| reason.contains(&format!("the Basepri write at {restore:#010x}")))
}

/// The frame address of the spill's word (`add r1, sp, #4`) leaves the registers for somewhere
/// the pass cannot place: after each `prelude` (before the spill) it is in `[sp, #8]` or in a
/// register the pass does not follow, and `between` reads it back into r3 and stores through it;
/// or `between` hands it to the debugger. The store may be the spill's word. (Before, the address
/// was lost without escaping, and the restore was believed.)
#[test]
fn a_frame_address_stored_where_the_pass_cannot_place_it_escapes() {
    let read_back = [0x9b02, 0x601c]; // ldr r3, [sp, #8]; str r4, [r3]
    let cases: [(&str, &[u16], &[u16]); 7] = [
        (
            "a register offset",
            // movs r2, #8; str.w r1, [sp, r2]
            &[0xa901, 0x2208, 0xf84d, 0x1002],
            &read_back,
        ),
        (
            "a conditional store",
            // cmp r2, #0; it ne; strne r1, [sp, #8]
            &[0xa901, 0x2a00, 0xbf18, 0x9102],
            &read_back,
        ),
        (
            "an exclusive store",
            // strex r0, r1, [sp, #8]
            &[0xa901, 0xe84d, 0x1002],
            &read_back,
        ),
        (
            "a floating-point store",
            // vmov s0, r1; vstr s0, [sp, #8]
            &[0xa901, 0xee00, 0x1a10, 0xed8d, 0x0a02],
            &read_back,
        ),
        (
            "a floating-point register",
            // vmov s0, r1 / vmov r3, s0; str r4, [r3]
            &[0xa901, 0xee00, 0x1a10],
            &[0xee10, 0x3a10, 0x601c],
        ),
        (
            // A write of PSP may move SP (in thread mode, where CONTROL selects PSP): SP's offset
            // is then unknown and no word is followed.
            "the process stack pointer",
            // msr PSP, r1 / mrs r3, PSP; str r4, [r3]
            &[0xa901, 0xf381, 0x8809],
            &[0xf3ef, 0x8309, 0x601c],
        ),
        (
            // The debugger reads and writes memory through the block r1 points to.
            "a semihosting call's parameter block",
            &[],
            // add r1, sp, #4; movs r0, #5; bkpt 0xab
            &[0xa901, 0x2005, 0xbeab],
        ),
    ];
    let believed: Vec<&str> = cases
        .into_iter()
        .filter(|&(_, prelude, between)| !names_the_restore(prelude, between, RELOAD))
        .map(|(what, ..)| what)
        .collect();
    assert!(believed.is_empty(), "the restore believed: {believed:?}");
    // SP itself stored (`str.w sp, [sp, #8]`, before the spill: SP is then 24 below the entry's,
    // the spill's word 4 above it), read back and stored through at 4 above it.
    let prelude = [0xf8cd, 0xd008];
    let between = [0x9b02, 0x605c]; // ldr r3, [sp, #8]; str r4, [r3, #4]
    assert_unclear_after(&lock(&prelude, &between, RELOAD), &prelude, &between);
}

#[test]
fn an_escaped_word_that_holds_a_frame_address_lets_that_address_escape() {
    // The spill's address kept in `[sp, #8]` (a word the pass follows), then the address of that
    // word moved to a floating-point register (it escapes, nothing is forgotten): code holding
    // the escaped address reads the spill's address from it and stores through it.
    let between = [
        0xa901, // add r1, sp, #4
        0x9102, // str r1, [sp, #8]
        0xaa02, // add r2, sp, #8
        0xee00, 0x2a10, // vmov s0, r2: [sp, #8]'s address escapes
        0xee10, 0x3a10, // vmov r3, s0
        0x681d, // ldr r5, [r3]: the spill's address
        0x602c, // str r4, [r5]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

/// A frame address kept in a word the pass follows, loaded back by a load it does not place
/// exactly (through a register worked from SP, or through SP at an offset it cannot compute, or
/// only in part): the loaded value may be that address, and a store through it may be the
/// spill's word. (Before, such a load gave a value the pass took for no frame address.)
#[test]
fn a_frame_address_loaded_back_by_a_load_not_placed_word_by_word_stays_one() {
    let keep = [0xa901, 0x9102]; // add r1, sp, #4; str r1, [sp, #8]
    let reads: [(&str, &[u16]); 6] = [
        ("add r2, sp, #8; ldr r3, [r2]", &[0xaa02, 0x6813]),
        // The frame address is the index, the base a constant.
        (
            "add r2, sp, #8; movs r0, #0; ldr r3, [r0, r2]",
            &[0xaa02, 0x2000, 0x5883],
        ),
        ("mov r7, sp; ldr r3, [r7, #8]", &[0x466f, 0x68bb]),
        ("movs r2, #8; ldr.w r3, [sp, r2]", &[0x2208, 0xf85d, 0x3002]),
        ("ldrh.w r3, [sp, #8]", &[0xf8bd, 0x3008]),
        ("ldrb.w r3, [sp, #8]", &[0xf89d, 0x3008]),
    ];
    let believed: Vec<&str> = reads
        .into_iter()
        .filter(|&(_, read)| {
            let mut between = keep.to_vec();
            between.extend_from_slice(read);
            between.push(0x601c); // str r4, [r3]
            !names_the_restore(&[], &between, RELOAD)
        })
        .map(|(what, _)| what)
        .collect();
    assert!(believed.is_empty(), "the restore believed: {believed:?}");
    // Kept at an unaligned offset (`str.w r1, [sp, #10]`) and put together again from the two
    // aligned words it straddles.
    let between = [
        0xa901, // add r1, sp, #4
        0xf8cd, 0x100a, // str.w r1, [sp, #10]
        0x9b02, // ldr r3, [sp, #8]: its low half, in the top half
        0x9d03, // ldr r5, [sp, #12]: its high half, in the bottom half
        0x0c1b, // lsrs r3, r3, #16
        0xea43, 0x4305, // orr.w r3, r3, r5, lsl #16: the address
        0x601c, // str r4, [r3]
    ];
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // A floating-point load of it (`vldr d0, [sp, #8]`) lets it escape: a store through a
    // pointer read from memory may then be the spill's word.
    let mut between = keep.to_vec();
    between.extend_from_slice(&[0xed9d, 0x0b02, 0x6833, 0x601c]); // vldr; ldr r3, [r6]; str r4, [r3]
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}

#[test]
fn the_saved_mask_loaded_through_another_register_is_no_restore() {
    // `add r2, sp, #4; ldr r0, [r2]`: the spill's word, read through a register the pass knows
    // only as some frame address; the value is not followed, and the write is neither a raise
    // nor a restore.
    let between = [0xaa01];
    assert_unclear(&lock(&[], &between, 0x6810), &between);
}

#[test]
fn a_store_and_load_multiple_through_sp_are_followed_word_by_word() {
    // `stmia sp, {r2, r3}` without write-back stores r2 to [sp] and r3 to [sp, #4]: the saved
    // mask copied back over the spill keeps it. msr 2 + ldr 2 + stm 1 + 2 + ldr 2 + msr 2 = 11
    // cycles, 5 instructions. (Before, the pass forgot every word at a store multiple through SP
    // without write-back.)
    let between = [0x9b01, 0xe88d, 0x000c]; // ldr r3, [sp, #4]; stmia sp, {r2, r3}
    assert_eq!(
        found(&lock(&[], &between, RELOAD)),
        Ok(vec![(PRIORITY_5, 11, 5)])
    );
    // Another value stored there overwrites it.
    let between = [0xe88d, 0x000c]; // stmia sp, {r2, r3}
    assert_unclear(&lock(&[], &between, RELOAD), &between);
    // `ldmia sp, {r2, r3}` loads the spill into r3, copied to r0: msr 2 + ldm 1 + 2 + mov 1 +
    // msr 2 = 8 cycles, 4 instructions.
    let between = [0xe89d, 0x000c]; // ldmia sp, {r2, r3}
    assert_eq!(
        found(&lock(&[], &between, 0x4618)), // mov r0, r3
        Ok(vec![(PRIORITY_5, 8, 4)])
    );
}

#[test]
fn sp_read_through_a_special_register_is_a_frame_address() {
    // `mrs r3, MSP` (a handler runs on MSP): r3 is SP, 24 below the entry's, the spill's word 4
    // above it. (Before, r3 was taken for no frame address, and the store through it kept the
    // spill.)
    let between = [0xf3ef, 0x8308, 0x605c]; // mrs r3, MSP; str r4, [r3, #4]
    assert_unclear(&lock(&[], &between, RELOAD), &between);
}
