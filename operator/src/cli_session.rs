//! The command line of the operator's session commands — `console`, `drive`, `run`, `relay`, `health` — kept
//! beside `cli.rs` so the one-shot commands and the session commands can grow without stepping on each other.

use std::path::PathBuf;

use clap::Args;

use crate::script::DriveWords;

const BUS_HELP: &str = "The bus: socketcan:IFACE, slcan:DEVICE or slcan:DEVICE@BAUD or file:PATH";

pub const CONSOLE_ABOUT: &str = "\
One screen for the thesis's Demo Sender and Demo Receiver: the bus scrolls by, decoded, at the top; commands \
are typed at the bottom in the words of `amiro encode` (Tab completes topics, priorities and options) or built \
from menus (F2), and the robot can be driven from the keyboard (F3).

Keys: Enter sends the command line; Tab completes; Up/Down recall earlier commands; PageUp/PageDown scroll \
(End follows the bus again); F2 menu; F3 drive mode (arrows change speed and turn, Space stops, Esc leaves); \
Ctrl-C or `quit` leaves (a moving robot is stopped first).

On an SLCAN adapter other amiro commands can run at the same time: they go through this one.";

pub const CONSOLE_HELP: &str = "\
Command line words (as in `amiro encode`, plus drive), with flags or said in words:
  publish gyroscope --every 10ms --priority high      publish gyroscope every 10ms at high
  once floor-proximity --priority medium              once floor
  stop gyroscope --priority high                      stop gyroscope at high
  led 3 --rgb 255,128,0                               led 3 orange, led 3 #FF8020
  drive --forward 100mm/s --turn 30deg/s --for 3s     drive 100mm/s turn 30deg/s for 3s
  205#01840302                      a raw frame
  stop-driving, clear, help, quit

Examples:
  amiro console --bus slcan:/dev/ttyUSB0
  amiro console --bus socketcan:can0 --sensor-data
  amiro console --bus slcan:/dev/ttyUSB0 --headless < commands.txt      no screen: lines from standard input";

/// `amiro console`.
#[derive(Debug, Args)]
pub struct ConsoleArgs {
    #[doc = "The bus: socketcan:IFACE, slcan:DEVICE or slcan:DEVICE@BAUD or file:PATH"]
    #[arg(long, env = "AMIRO_BUS", value_name = "BUS", help = BUS_HELP)]
    pub bus: String,

    /// Show only sensor data in the bus view (commands are still sent and confirmed)
    #[arg(long)]
    pub sensor_data: bool,

    /// No screen: read command lines from standard input, print the bus view to standard output, and end when
    /// the input ends (for scripts and tests)
    #[arg(long)]
    pub headless: bool,

    /// With --headless: keep watching this long after the input ended, e.g. 500ms
    #[arg(long, value_name = "DURATION", default_value = "0s")]
    pub linger: String,

    /// The robot's revision, whose boards' tables the admission check uses [default: AMIRO_REVISION, else 1-1]
    #[arg(long, value_name = "REVISION", value_parser = crate::admission::REVISIONS)]
    pub revision: Option<String>,
}

pub const DRIVE_ABOUT: &str = "\
Drive the robot: the motor command is sent at once and repeated every 200 ms, because the DiWheelDrive stops the \
motors when no motor command arrived for 500 ms (its dead-man). At the end of --for, on Ctrl-C, or when the \
bus fails, a stop is sent (if the bus is lost, the dead-man stops the robot within 500 ms of the last command). \
What the robot sends meanwhile is printed.

Exit status: 0 after the drive and the stop; 1 if the bus failed.";

pub const DRIVE_HELP: &str = "\
Units: forward in mm/s, cm/s, m/s or um/s (negative: backwards); turn in deg/s, rad/s, mrad/s or urad/s
(positive: counter-clockwise seen from above).

Examples:
  amiro drive --forward 100mm/s --for 3s --bus slcan:/dev/ttyUSB0
  amiro drive --forward 50mm/s --turn 30deg/s --for 5s --bus socketcan:can0
  amiro drive --turn -90deg/s --bus socketcan:can0          turn clockwise until Ctrl-C";

/// `amiro drive`.
#[derive(Debug, Args)]
pub struct DriveArgs {
    /// How to drive.
    #[command(flatten)]
    pub motion: DriveWords,

    #[arg(long, env = "AMIRO_BUS", value_name = "BUS", help = BUS_HELP)]
    pub bus: String,

    /// Print what comes back as JSON Lines
    #[arg(long)]
    pub json: bool,
}

pub const RUN_ABOUT: &str = "\
Play a script: one step per line, in the words of `amiro encode` (publish, stop, once, motor, led) with flags or \
said in words (`publish gyroscope every 100ms at high`, `led 3 red`, `drive 100mm/s for 2s`), raw frames \
(205#01840302), `wait DURATION` (watch the bus meanwhile) and `drive --forward SPEED --turn RATE --for DURATION` \
(kept alive within the dead-man, then stopped). Lines starting with # are comments. The whole script is checked \
before anything is sent. Everything the robot sends back is printed with the time since the start.

On Ctrl-C the script stops; a drive in progress is stopped first.

Exit status: 0 when the script ran to its end; 1 if it could not be read or the bus failed; 130 on Ctrl-C.";

pub const RUN_HELP: &str = "\
Example script (operator/examples/standalone-demo.amiro, the thesis's Demo Standalone):
  publish gyroscope --every 100ms --priority high
  wait 1s
  drive --forward 50mm/s --turn 0deg/s --for 2s
  led 3 --rgb 0,50,120

Examples:
  amiro run operator/examples/standalone-demo.amiro --bus slcan:/dev/ttyUSB0
  amiro run demo.amiro --check                    parse and list the frames, send nothing";

/// `amiro run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The script file (`-` is standard input)
    #[arg(value_name = "SCRIPT")]
    pub script: PathBuf,

    #[arg(long, env = "AMIRO_BUS", value_name = "BUS", help = BUS_HELP, required_unless_present = "check")]
    pub bus: Option<String>,

    /// Only check the script and print the frames it would send
    #[arg(long)]
    pub check: bool,

    /// Send raw frames even if the AMiRo decoder rejects them
    #[arg(long)]
    pub raw: bool,

    /// Print what comes back as JSON Lines
    #[arg(long)]
    pub json: bool,
}

pub const RELAY_ABOUT: &str = "\
Open an SLCAN adapter and hold it, so that any number of other amiro commands (monitor, send, console, drive, \
run) share it; they find this one by the device name. Any amiro that opens an adapter first does the same for \
as long as it runs; `relay` is for a session in which the first command should not be the one that holds the \
adapter. Ends on Ctrl-C, closing the adapter's channel; connected commands then report the lost bus.";

/// `amiro relay`.
#[derive(Debug, Args)]
pub struct RelayArgs {
    /// The adapter: slcan:DEVICE or slcan:DEVICE@BAUD
    #[arg(long, env = "AMIRO_BUS", value_name = "BUS")]
    pub bus: String,
}

pub const RECORD_ABOUT: &str = "\
Record a bus into an MCAP file, the format of ROS 2 recordings and of Foxglove. Every frame goes to the channel \
/amiro/frames (as `amiro decode --json` describes it); each topic's decoded samples go to /amiro/TOPIC (e.g. \
/amiro/gyroscope with x_dps, y_dps, z_dps: the field names of `decode --json`, in protocol units) and commands to \
/amiro/TOPIC/command, each channel with a JSON schema. A message's log time is the time its frame was received \
(or its timestamp in a log file). Ends after --duration, at the end of a log file, or on Ctrl-C; the file is \
complete in every case.";

pub const RECORD_HELP: &str = "\
Examples:
  amiro record --bus slcan:/dev/ttyUSB0 --out run.mcap --duration 30s
  amiro record --bus socketcan:can0 --out run.mcap                     until Ctrl-C
  amiro record --bus file:candump.log --out run.mcap                   convert a log (or: amiro decode --mcap)
Open the file in Foxglove (File > Open local file) and plot /amiro/gyroscope.x_dps.";

/// `amiro record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    #[arg(long, env = "AMIRO_BUS", value_name = "BUS", help = BUS_HELP)]
    pub bus: String,

    /// The MCAP file to write (replaced if it exists)
    #[arg(long, value_name = "FILE.mcap")]
    pub out: PathBuf,

    /// Stop after this long, e.g. 30s (without it: until Ctrl-C or the end of a log file)
    #[arg(long, value_name = "DURATION", value_parser = parse_duration_arg)]
    pub duration: Option<std::time::Duration>,

    /// A virtual robot's world (`cargo xtask robot --world FILE`): its walls, obstacles and floor go on
    /// `/world/arena` for Foxglove's 3D panel
    #[arg(long, value_name = "FILE.json")]
    pub world: Option<PathBuf>,

    /// That run's trajectory (`--trajectory OUT.csv`): the robot's pose at every row on `/world/pose`. Record
    /// the run's own bus log (`--bus file:…/bus.log`): its times are the trajectory's virtual time
    #[arg(long, value_name = "FILE.csv")]
    pub trajectory: Option<PathBuf>,
}

fn parse_duration_arg(text: &str) -> Result<std::time::Duration, String> {
    crate::period::parse_duration(text).map_err(|error| error.to_string())
}
