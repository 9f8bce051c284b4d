//! The `amiro` command: talk to the robot over CAN from the operator computer.
//!
//! `decode` and `encode` work offline on frame text; `send`, `monitor`, `console`, `drive` and `run` reach the
//! robot through a bus (SocketCAN, an SLCAN adapter — shared between `amiro` processes — or a candump log file). The protocol itself lives in `amiro-can`; this binary
//! adds text formats, transports and words for people.

use std::process::ExitCode;

use clap::Parser;

use operator::cli::{Cli, CliCommand};
use operator::{commands, console, health, session};

fn main() -> ExitCode {
    let cli = Cli::parse();
    let outcome = match &cli.command {
        CliCommand::Decode(args) => commands::decode(args),
        CliCommand::Encode(args) => commands::encode(args),
        CliCommand::Send(args) => commands::send(args),
        CliCommand::Monitor(args) => commands::monitor(args),
        CliCommand::Topics => commands::topics(),
        CliCommand::Dbc(args) => commands::dbc(args),
        CliCommand::Console(args) => console::run(args),
        CliCommand::Drive(args) => session::drive_command(args),
        CliCommand::Run(args) => session::run(args),
        CliCommand::Record(args) => session::record(args),
        CliCommand::Relay(args) => session::relay(args),
        CliCommand::Health(args) => health::health(args),
    };
    match outcome {
        Ok(code) => code,
        // `amiro decode ... | head` closes our output early: that is the reader's choice, not an error.
        Err(error) if is_broken_pipe(&error) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error
        .chain()
        .filter_map(|cause| cause.downcast_ref::<std::io::Error>())
        .any(|io_error| io_error.kind() == std::io::ErrorKind::BrokenPipe)
}
