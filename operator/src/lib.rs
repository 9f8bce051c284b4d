//! The operator computer's side of the AMiRo robot as a library: frame text formats (`frame`: can-utils,
//! `candump -l`), periods, plain-English descriptions, transports (`bus`: SocketCAN, SLCAN, candump logs, the
//! relay), the host-side admission check, recordings, the dashboard and the console. The `amiro` binary
//! (`src/main.rs`) only parses its arguments and calls `commands`; the robot emulation and the example behaviours
//! use the same codecs from here. The protocol itself lives in `amiro-can`.

pub mod admission;
pub mod bus;
pub mod cli;
pub mod cli_session;
pub mod commands;
pub mod console;
pub mod dashboard;
pub mod dbc;
pub mod describe;
pub mod drive;
pub mod encode;
pub mod frame;
pub mod health;
#[cfg(feature = "foxglove")]
pub mod live;
pub mod period;
pub mod record;
pub mod script;
pub mod session;
pub mod speech;
pub mod watch;
