//! The robot link: what a board's QEMU build and `cargo xtask robot`'s host exchange every quantum
//! over the board's semihosting files (docs/qemu.md, "The whole robot"). Both sides take the
//! layout from here, so they cannot drift apart.

/// The exchange period in virtual µs: a multiple of the 10 µs tick below the shortest frame (44 bit
/// times from start of frame to completion at 1 Mbit/s).
pub const QUANTUM_US: u64 = 40;
/// Board → host: `u64` now, `u8` new frames, `u8` lines driven, `u8` abort requests ([`UP_ABORTS`]),
/// 1 reserved, `u32` µs the board sleeps from now (0: it has work; `u32::MAX`: no deadline), three
/// 20-byte records (`u64` queued at, `u16` id, `u8` length, `u8` mailbox, 8 data bytes).
pub const UP_LEN: usize = 16 + 3 * 20;
/// Host → board: `u64` completion time, `u8` flags, `u8` mailbox, `u16` id, `u8` length, `u8`
/// aborted mailboxes ([`DOWN_ABORTED`]), 2 reserved, 8 data bytes, `u64` time of the next exchange
/// (0: one quantum on).
pub const DOWN_LEN: usize = 32;
/// Up, the byte at this offset: bit `k` asks the host to abort mailbox `k`'s frame (bxCAN's ABRQ: the
/// driver displaces its least urgent frame for a more urgent one when all three mailboxes are full).
pub const UP_ABORTS: usize = 10;
/// Down, the byte at this offset: bit `k`, mailbox `k`'s frame was aborted before its transmission
/// started (it is free now, and the board's transmit interrupt hands the frame back); an abort that
/// comes too late is not answered (the frame completes as it would have).
pub const DOWN_ABORTED: usize = 13;

/// Up: this board pulls SYS_SYNC_N low.
pub const DRIVES_SYNC_LOW: u8 = 1;
/// Up: this board drives SYS_PD_N low.
pub const DRIVES_PD_LOW: u8 = 2;
/// Down: a frame completes in this quantum.
pub const DOWN_FRAME: u8 = 1;
/// Down: the frame is this board's own (its mailbox is free at the completion time).
pub const DOWN_OWN: u8 = 2;
/// Down: SYS_PD_N reads low.
pub const DOWN_PD_LOW: u8 = 4;
/// Down: SYS_SYNC_N reads low.
pub const DOWN_SYNC_LOW: u8 = 8;
/// Down: the run is over.
pub const DOWN_END: u8 = 16;
