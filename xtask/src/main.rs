//! Project automation: `cargo xtask build | check | test | analyze | flash | qemu | ci`.
fn main() {}
