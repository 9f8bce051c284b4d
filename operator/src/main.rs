//! The `amiro` command: talk to the robot over CAN from the operator computer.
fn main() {}
