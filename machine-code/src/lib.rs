//! Analyses of a built firmware image's machine code, for the host: every check the build makes of what
//! the boards run, read from the ELF the linker wrote rather than from the source.
//!
//! - [`image`]: the ELF read once ([`Image::read`], [`Image::parse`]): named functions, their Thumb-2
//!   code decoded with `yaxpeax-arm` (literal pools skipped by the `$d` mapping symbols), the vector
//!   table, the functions whose address is stored, flash contents, and the DWARF line table.
//! - [`callgraph`]: direct calls and tail calls; the panic check of the on-chip admission analysis.
//! - [`stack`]: the static stack bound (frames summed along the deepest call chain, nested handlers).
//! - [`waits`]: the poll-loop scan (a loop polling a peripheral register without a counter).
//! - [`elf`]: what a flasher and a trace reader need of an image (loadable segments, symbols).
//! - [`wcet`]: execution-time bounds in cycles on the target chip (docs/analysis.md, "Execution-time
//!   bounds from the machine code").
//!
//! # The execution-time API (stable; `cargo xtask wcet` and the schedule analysis call it)
//!
//! ```text
//! let image = Image::read(path)?;                       // or Image::parse(&bytes)
//! let bounds = BoundsFile::read(path)?;                 // or BoundsFile::default() / ::parse(json)
//! let chip = Chip::Stm32f103 { wait_states: 2 };        // or Chip::Stm32f405 { wait_states: 5 }
//! let bound: Bound = bound_function(&image, "symbol", chip, &bounds)?;
//! let rows: Vec<TaskBound> = bound_tasks(&image, &tasks, chip, &bounds);
//! let sections: Vec<TaskSections> = task_sections(&image, &tasks, chip, &bounds);
//! ```
//!
//! - [`bound_function`] bounds one function (its demangled name without hash, or its raw symbol) with
//!   every function it calls. `Err(Error)` only for a bad image, a missing symbol or code the decoder
//!   cannot follow; a function that cannot be bounded (a loop without a bound, recursion, an
//!   unresolved indirect call) is `Ok` with [`Bound::declined`] naming the reason and the loop
//!   (function, file:line), and no figures to use.
//! - [`Bound`]: `cycles` (machine-code cycles on the longest path, exception entry and exit not
//!   included), `instructions` (the largest instruction count of any path, bounded loops unrolled to
//!   their bound), `bus_wait_ns` (stated peripheral waits on the longest path, apart from the
//!   cycles), `loops` ([`LoopInfo`]: function, file:line, bound, where the bound came from),
//!   `retry_cycles`/`retry_instructions` (what one preemption inside an exclusive-access sequence
//!   adds), `declined`.
//! - [`bound_tasks`] bounds a list of [`Task`]s (a name and an entry: a symbol, an interrupt's
//!   vector index, or one software task's part of the RTIC dispatcher that polls it,
//!   [`TaskEntry::Polled`]) into [`TaskBound`] rows (`cycles`, `us`, `instructions`, `bus_wait_us`, `loops`,
//!   `preemption_retry_cycles`, `declined`); a handler adds the exception entry and exit (and lazy
//!   FPU stacking on the M4F) and the longest retry iteration of any task it may preempt.
//! - [`task_sections`] finds every critical section the same tasks' code can hold (an RTIC lock's
//!   `MSR BASEPRI_MAX` to its `MSR BASEPRI`, `CPSID i` to `MSR PRIMASK`), bounds each from the raise
//!   to the restore, and gives per task the longest at each [`Ceiling`] ([`CeilingBound`], declined
//!   with the section named where a loop in it has no bound), or says why the list may be
//!   incomplete ([`TaskSections::incomplete`]).
//!
//! Every error is an [`Error`]; nothing here panics on a malformed image.
pub mod callgraph;
pub mod decode;
pub mod elf;
pub mod error;
pub mod image;
pub mod stack;
#[cfg(test)]
pub(crate) mod testelf;
pub mod waits;
pub mod wcet;

pub use error::Error;
pub use image::Image;
pub use wcet::bounds::BoundsFile;
pub use wcet::chip::Chip;
pub use wcet::{
    bound_function, bound_tasks, task_sections, topic_sections, ActivationBound, Bound, Ceiling,
    CeilingBound, FrameBound, LoopInfo, Part, Task, TaskBound, TaskEntry, TaskSections, TopicBound,
};

/// Thumb halfwords as the bytes of an image (tests of the decoders).
#[cfg(test)]
pub(crate) fn thumb(halves: &[u16]) -> Vec<u8> {
    halves.iter().flat_map(|h| h.to_le_bytes()).collect()
}
