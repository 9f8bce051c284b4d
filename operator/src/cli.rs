//! The command line: every subcommand, option and help text of `amiro`, declared with clap's derive API.
//!
//! Help is written for someone who has never read the thesis: each subcommand explains what the robot does with
//! the frame and ends with examples that can be pasted as they are.

use std::path::PathBuf;

use amiro_can::{AdmissionPolicy, Board, Priority, Rgb, ShutdownMode, Topic, TOPICS};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};

const ABOUT: &str =
    "Talk to the AMiRo robot over CAN: decode frames, build commands, send them, watch the bus";

const LONG_ABOUT: &str = "\
Talk to the AMiRo robot over its CAN bus.

Every board of the robot shares one CAN bus. A frame has an 11-bit identifier and up to 8 data bytes, written \
here the way the Linux can-utils write them: 205#01840302 is identifier 0x205 with the bytes 01 84 03 02. \
The identifier says whether the frame is a command (to a board) or sensor data (from a board), its \
priority (urgent, high, medium, low), and its topic (gyroscope, motor, led-3, ...).

To get sensor data you send a command to the sensor's topic: publish (send samples every so often), once \
(send one sample now) or stop. The board then sends the samples with the same priority as the command.

Run `amiro topics` to see every topic, and `amiro <command> --help` for each command.";

const EXAMPLES: &str = "\
Examples:
  amiro decode 205#01840302
  amiro encode publish magnetometer-x --every 900us --priority medium
  amiro send publish gyroscope --every 50ms --priority high --bus socketcan:can0
  amiro monitor --bus slcan:/dev/ttyUSB0 --count 10
  candump -l can0   # then: amiro decode --file candump-*.log";

/// The `amiro` command line.
#[derive(Debug, Parser)]
#[command(name = "amiro", version, about = ABOUT, long_about = LONG_ABOUT, after_help = EXAMPLES)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: CliCommand,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum CliCommand {
    /// Explain frames in plain English (or JSON)
    #[command(
        long_about = "\
Explain CAN frames in plain English: who they are for, their priority, and the command or the sensor values \
they carry, with units and signs. A frame the robot would reject is reported with the reason, and decoding \
goes on with the next one.

Frames come from the command line, from a file (--file), or from standard input. Accepted forms:
  205#01840302                              can-utils (cansend) form
  (1700000000.123456) can0 605#D8ADFFFF     a line of `candump -l` log
  can0  205   [4]  01 84 03 02              what `candump can0` prints on screen
Blank lines and lines starting with # or // are skipped; other lines that are not frames are reported.

Exit status: 0 if every frame decoded, 1 if some frame or line could not be (all are still reported).",
        after_help = "\
Examples:
  amiro decode 205#01840302
      says: medium command magnetometer-x: publish every 900 µs (samples arrive on 605)
  amiro decode 608#FCFF1E00FBFF --json
  amiro decode --file candump-2024-01-01_120000.log
  amiro decode --file candump-2024-01-01_120000.log --mcap run.mcap     the same frames for Foxglove
  candump -L can0 | amiro decode"
    )]
    Decode(DecodeArgs),

    /// Build a command frame and print it as ID#DATA
    #[command(
        long_about = "\
Build a command frame and print it in can-utils form (ID#DATA), ready for `cansend can0 ...` or \
`amiro send`. Nothing is sent.",
        after_help = "\
Examples:
  amiro encode publish magnetometer-x --every 900us --priority medium     prints 205#01840302
  amiro encode once floor-proximity --priority medium                     prints 204#02
  amiro encode stop gyroscope --priority low                              prints 308#00
  amiro encode motor --velocity 100000 --angular -500000
  amiro encode led 3 --rgb 255,128,0"
    )]
    Encode(EncodeArgs),

    /// Put frames on a bus
    #[command(
        long_about = "\
Put frames on a bus. Give either frames (ID#DATA, as `encode` prints them) or the same words as `encode`. \
Each frame is checked with the AMiRo decoder first; one the robot would reject is not sent (unless --raw). \
Each sent frame is echoed with its meaning.",
        after_help = "\
Bus URLs (--bus, or the AMIRO_BUS environment variable):
  socketcan:can0                  Linux SocketCAN interface (bring it up first:
                                  ip link set can0 up type can bitrate 1000000)
  slcan:/dev/ttyUSB0[@115200]     USB-serial adapter speaking SLCAN (Lawicel); opened at 1 Mbit/s
  file:frames.log                 append candump -l lines to a file (replay with canplayer)

Examples:
  amiro send 205#01840302 --bus socketcan:can0
  amiro send publish gyroscope --every 10ms --priority high --bus slcan:/dev/ttyACM0
  amiro send motor --velocity 50000 --angular 0 --bus socketcan:can0
  amiro send stop gyroscope --priority high --bus socketcan:can0",
        args_conflicts_with_subcommands = true
    )]
    Send(SendArgs),

    /// Watch a bus and explain every frame
    #[command(
        long_about = "\
Watch a bus and explain every frame as it arrives, like `decode` does. Stops after --count frames, after \
--timeout, at the end of a log file, or on Ctrl-C (an SLCAN adapter's channel is closed properly).

Exit status: 0 normally; 1 if --count frames did not arrive before the timeout or the end of the log.",
        after_help = "\
Bus URLs (--bus, or the AMIRO_BUS environment variable):
  socketcan:can0                  Linux SocketCAN interface
  slcan:/dev/ttyUSB0[@115200]     USB-serial adapter speaking SLCAN (Lawicel); opened at 1 Mbit/s
  file:candump.log                read a candump -l log (add --realtime to keep its timing)

Examples:
  amiro monitor --bus socketcan:can0
  amiro monitor --bus slcan:/dev/ttyUSB0 --count 8 --timeout 2s --json
  amiro monitor --bus file:candump-2024-01-01_120000.log --realtime
  amiro monitor --bus socketcan:can0 --dashboard                 one live row per topic
  amiro monitor --bus slcan:/dev/ttyUSB0 --record run.mcap       and keep it for Foxglove"
    )]
    Monitor(MonitorArgs),

    /// List every topic: identifier byte, board, payload and default period
    #[command(after_help = "\
A command to topic T at priority P has identifier (P << 8) | T, its sensor data (0x400 | (P << 8) | T).
Example: magnetometer-x is 0x05; at medium priority (2) the command is 0x205 and the data 0x605.")]
    Topics,

    /// Write the whole protocol as a DBC file (for cantools, SavvyCAN, Vector tools)
    #[command(after_help = "\
Every identifier is one message: each topic's command and (for sensors) its data, at all four priorities,
with scaled signals and units; pages of multi-frame topics are multiplexed signals.

Examples:
  amiro dbc --output amiro.dbc
  python3 -c 'import cantools; db = cantools.database.load_file(\"amiro.dbc\"); print(db.decode_message(0x508, bytes.fromhex(\"FCFF1E000500\")))'")]
    Dbc(DbcArgs),

    /// One screen to command and watch the robot: live decoded bus, command line with completion, menus, driving
    #[command(long_about = crate::cli_session::CONSOLE_ABOUT, after_help = crate::cli_session::CONSOLE_HELP)]
    Console(crate::cli_session::ConsoleArgs),

    /// Drive for a while, repeating the motor command within the board's dead-man, then stop
    #[command(long_about = crate::cli_session::DRIVE_ABOUT, after_help = crate::cli_session::DRIVE_HELP)]
    Drive(crate::cli_session::DriveArgs),

    /// Play a script: timed commands, waits and drives, printing what comes back
    #[command(long_about = crate::cli_session::RUN_ABOUT, after_help = crate::cli_session::RUN_HELP)]
    Run(crate::cli_session::RunArgs),

    /// Record a bus into an MCAP file for Foxglove: one channel per topic, raw frames, log time = frame time
    #[command(long_about = crate::cli_session::RECORD_ABOUT, after_help = crate::cli_session::RECORD_HELP)]
    Record(crate::cli_session::RecordArgs),

    /// Hold an SLCAN adapter and share it with other amiro commands until Ctrl-C
    #[command(long_about = crate::cli_session::RELAY_ABOUT)]
    Relay(crate::cli_session::RelayArgs),

    /// Ask every board for its health over CAN (diagnostics counters) and say what looks wrong
    #[command(long_about = crate::health::HEALTH_ABOUT, after_help = crate::health::HEALTH_HELP)]
    Health(crate::health::HealthArgs),
}

/// `amiro dbc`.
#[derive(Debug, Args)]
pub struct DbcArgs {
    /// Write to this file instead of standard output
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// `amiro decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// Frames to decode, e.g. 205#01840302 (none: read --file or standard input)
    #[arg(value_name = "FRAME", conflicts_with = "file")]
    pub frames: Vec<String>,

    /// Read frames from this file, one per line (`-` is standard input)
    #[arg(long, short, value_name = "FILE")]
    pub file: Option<PathBuf>,

    /// Print one JSON object per line instead of English (schema in docs/operator.md)
    #[arg(long)]
    pub json: bool,

    /// Also write the frames into this MCAP file (for Foxglove): one channel per topic, log time = frame time
    #[arg(long, value_name = "FILE.mcap")]
    pub mcap: Option<PathBuf>,
}

/// `amiro encode`.
#[derive(Debug, Args)]
pub struct EncodeArgs {
    /// The command to build.
    #[command(subcommand)]
    pub message: MessageArgs,
}

/// A command to build, shared by `encode` and `send`.
#[derive(Debug, Clone, Subcommand)]
pub enum MessageArgs {
    /// Start (or change) a sensor's publisher: samples every PERIOD
    #[command(
        long_about = "\
Start a sensor's publisher, or change the period and priority of one that runs: the board then sends a \
sample every PERIOD, with the priority of this command. The period is sent as a 16-bit count of µs, ms or \
s; the unit you write is kept if it fits, otherwise one that holds the period exactly is chosen (70000us is \
sent as 70 ms). A period with no exact encoding, zero, or longer than the firmware can schedule \
(4294.967295 s) is refused.",
        after_help = "\
Examples:
  amiro encode publish magnetometer-x --every 900us --priority medium     205#01840302
  amiro encode publish gyroscope --every 10ms --priority high             108#010A0000
  amiro encode publish power-status --every 2s --priority low             31E#01020001"
    )]
    Publish {
        /// The sensor topic
        #[arg(value_name = "TOPIC", value_parser = sensor_topic_parser())]
        topic: Topic,
        /// Time between samples: a number and a unit, e.g. 900us (or 900µs), 50ms, 1.5s
        #[arg(long, value_name = "PERIOD")]
        every: String,
        /// Priority of the command and of every sample the board sends back
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser())]
        priority: Priority,
    },

    /// Stop a sensor's publisher
    #[command(after_help = "\
Example:
  amiro encode stop magnetometer-x --priority medium                      205#00")]
    Stop {
        /// The sensor topic
        #[arg(value_name = "TOPIC", value_parser = sensor_topic_parser())]
        topic: Topic,
        /// Priority of the command frame
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser())]
        priority: Priority,
    },

    /// Ask a sensor for one sample now (this also stops its publisher)
    #[command(after_help = "\
Example:
  amiro encode once floor-proximity --priority medium                     204#02")]
    Once {
        /// The sensor topic
        #[arg(value_name = "TOPIC", value_parser = sensor_topic_parser())]
        topic: Topic,
        /// Priority of the command and of the sample sent back
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser())]
        priority: Priority,
    },

    /// Drive: set the forward and turning velocity of the wheels
    #[command(
        long_about = "\
Set the target velocity of the differential drive (DiWheelDrive board): forward velocity in µm/s \
(100000 = 10 cm/s, negative = backwards) and turning rate in µrad/s (1000000 ≈ 57°/s, positive = \
counter-clockwise seen from above). 0 and 0 stops the robot.

Dead-man: the DiWheelDrive stops the motors when no motor command arrived for 500 ms, so one frame drives \
for half a second. To keep driving, repeat the command faster than that: `amiro drive --forward 100mm/s \
--for 3s` does (every 200 ms, then a stop), and so do the console's teleoperation and scripts.",
        after_help = "\
Examples:
  amiro encode motor --velocity 100000 --angular 0          10 cm/s straight ahead
  amiro encode motor --velocity 0 --angular -500000         turn clockwise on the spot
  amiro encode motor --velocity 0 --angular 0 --priority urgent      stop"
    )]
    Motor {
        /// Forward velocity in µm/s (negative: backwards)
        #[arg(long, value_name = "UM_PER_S", allow_negative_numbers = true)]
        velocity: i32,
        /// Turning rate in µrad/s (positive: counter-clockwise)
        #[arg(long, value_name = "URAD_PER_S", allow_negative_numbers = true)]
        angular: i32,
        /// Priority of the command frame
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser(), default_value = "high")]
        priority: Priority,
    },

    /// Set the colour of one of the 8 LEDs of the light ring
    #[command(after_help = "\
Examples:
  amiro encode led 1 --rgb 255,0,0                                        311#FF0000
  amiro encode led 8 --rgb 0,0,0 --priority high                          118#000000
  amiro encode led 3 --rgb '#FF8000'                                      313#FF8000")]
    Led {
        /// Which LED, 1 to 8
        #[arg(value_name = "LED", value_parser = clap::value_parser!(u8).range(1..=8))]
        led: u8,
        /// Colour as red,green,blue (each 0-255) or #RRGGBB
        #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
        rgb: Rgb,
        /// Priority of the command frame
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser(), default_value = "low")]
        priority: Priority,
    },

    /// Shut the whole robot down (PowerManagement, the power master, carries it out)
    #[command(
        long_about = "\
Shut the robot down: PowerManagement pulls SYS_PD_N so every board stops, writes MODE where the AMiRo-BLT \
bootloader reads it (RTC backup register) and hands over to the bootloader. hibernate: everything off, wakes \
on the charger or a button; deep-sleep: everything off, a wake-up source restarts it; transportation: off \
with the fewest wake-up sources, for shipping; restart: power-cycle and boot again.",
        after_help = "\
Examples:
  amiro encode shutdown transportation                                   01D#0355AA
  amiro encode shutdown restart --priority high                          11D#0455AA"
    )]
    Shutdown {
        /// What to do
        #[arg(value_name = "MODE", value_parser = shutdown_mode_parser())]
        mode: ShutdownMode,
        /// Priority of the command frame
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser(), default_value = "urgent")]
        priority: Priority,
    },

    /// Choose how a board answers a request that would make it miss a deadline
    #[command(
        long_about = "\
Set a board's admission policy. refuse (the default after reset): a publish or re-prioritisation request \
that would make a task or a frame miss its deadline is refused, nothing changes, and the board says why \
(an admission verdict on its diagnostics topic, which `amiro decode`/`monitor` print). accept-and-warn: the \
board carries the request out and sends the same verdict as a warning.",
        after_help = "\
Examples:
  amiro encode policy diwheeldrive accept-and-warn                       21A#0301
  amiro encode policy powermanagement refuse                             21B#0300"
    )]
    Policy {
        /// The board
        #[arg(value_name = "BOARD", value_parser = board_parser())]
        board: Board,
        /// refuse or accept-and-warn
        #[arg(value_name = "POLICY", value_parser = policy_parser())]
        policy: AdmissionPolicy,
        /// Priority of the command frame
        #[arg(long, value_name = "PRIORITY", value_parser = priority_parser(), default_value = "medium")]
        priority: Priority,
    },
}

/// `amiro send`.
#[derive(Debug, Args)]
pub struct SendArgs {
    /// Build the frame from words, as `amiro encode` does.
    #[command(subcommand)]
    pub message: Option<MessageArgs>,

    /// Frames to send in order, e.g. 205#01840302
    #[arg(value_name = "FRAME")]
    pub frames: Vec<String>,

    /// Read the frames from a file, one per line (`-` is standard input); candump -l logs work too
    #[arg(long, short, value_name = "FILE", conflicts_with = "frames")]
    pub file: Option<PathBuf>,

    /// The bus: socketcan:IFACE, slcan:DEVICE or slcan:DEVICE@BAUD or file:PATH
    #[arg(long, env = "AMIRO_BUS", global = true, value_name = "BUS")]
    pub bus: Option<String>,

    /// Send frames even if the AMiRo decoder rejects them (testing a board's error handling)
    #[arg(long, global = true)]
    pub raw: bool,

    /// Before a publish request leaves, listen this long to learn what the robot runs (commands and sensor
    /// data heard), so the admission check sees the robot as it is [default: 1s on a live bus; 0s skips it]
    #[arg(long, global = true, value_name = "DURATION", value_parser = parse_timeout)]
    pub listen: Option<std::time::Duration>,

    /// Learn what the robot runs from a log of its bus (candump -l or any form `decode` reads), before listening
    #[arg(long, global = true, value_name = "FILE")]
    pub heard: Option<PathBuf>,

    /// The robot's revision, whose boards' tables the admission check uses [default: AMIRO_REVISION, else 1-1]
    #[arg(long, global = true, value_name = "REVISION", value_parser = crate::admission::REVISIONS)]
    pub revision: Option<String>,
}

/// `amiro monitor`.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// The bus: socketcan:IFACE, slcan:DEVICE or slcan:DEVICE@BAUD or file:PATH
    #[arg(long, env = "AMIRO_BUS", value_name = "BUS")]
    pub bus: String,

    /// The robot's revision, whose boards' tables explain the admission verdicts heard [default: AMIRO_REVISION,
    /// else 1-1]
    #[arg(long, value_name = "REVISION", value_parser = crate::admission::REVISIONS)]
    pub revision: Option<String>,

    /// Print one JSON object per line instead of English
    #[arg(long)]
    pub json: bool,

    /// Stop after this many frames
    #[arg(long, short = 'n', value_name = "N")]
    pub count: Option<u64>,

    /// Stop after this long in total, e.g. 5s or 500ms
    #[arg(long, value_name = "DURATION", value_parser = parse_timeout)]
    pub timeout: Option<std::time::Duration>,

    /// With a file: bus, replay frames at the pace of their timestamps
    #[arg(long)]
    pub realtime: bool,

    /// Print absolute timestamps (seconds since 1970 on a live bus) instead of seconds since the start
    #[arg(long)]
    pub absolute: bool,

    /// Only frames of topics this board owns (repeatable)
    #[arg(long, value_name = "BOARD", value_parser = board_parser())]
    pub board: Vec<Board>,

    /// Only frames of this topic (repeatable), e.g. gyroscope
    #[arg(long, value_name = "TOPIC", value_parser = any_topic_parser())]
    pub topic: Vec<Topic>,

    /// Only sensor data (what the boards send), as the thesis's receiver shows
    #[arg(long)]
    pub sensor_data: bool,

    /// Do not print the summary (frames, period and jitter per topic) on exit
    #[arg(long)]
    pub no_summary: bool,

    /// Also record every frame heard into this MCAP file (for Foxglove; filters only choose what is printed)
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,

    /// Show a live dashboard instead of lines: one row per topic heard with its latest values, period and
    /// health (q or Ctrl-C leaves)
    #[arg(long, conflicts_with = "json")]
    pub dashboard: bool,

    /// Serve the bus live to Foxglove over its WebSocket protocol, on HOST:PORT [default: 127.0.0.1:8765]
    /// (the channels of an MCAP recording; needs the `foxglove` cargo feature)
    #[arg(long, value_name = "HOST:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub foxglove: Option<String>,
}

fn any_topic_parser() -> impl TypedValueParser<Value = Topic> {
    PossibleValuesParser::new(TOPICS.iter().map(|info| info.name))
        .try_map(|name| Topic::from_name(&name).ok_or_else(|| format!("unknown topic {name:?}")))
}

fn priority_parser() -> impl TypedValueParser<Value = Priority> {
    PossibleValuesParser::new(Priority::ALL.map(Priority::name)).try_map(|name| {
        Priority::from_name(&name).ok_or_else(|| format!("unknown priority {name:?}"))
    })
}

fn shutdown_mode_parser() -> impl TypedValueParser<Value = ShutdownMode> {
    PossibleValuesParser::new(ShutdownMode::ALL.map(ShutdownMode::name)).try_map(|name| {
        ShutdownMode::ALL
            .into_iter()
            .find(|mode| mode.name() == name)
            .ok_or_else(|| format!("unknown shutdown mode {name:?}"))
    })
}

fn board_parser() -> impl TypedValueParser<Value = Board> {
    PossibleValuesParser::new(["diwheeldrive", "powermanagement", "lightring"]).try_map(|name| {
        Board::ALL
            .into_iter()
            .find(|board| board.name().eq_ignore_ascii_case(&name))
            .ok_or_else(|| format!("unknown board {name:?}"))
    })
}

fn policy_parser() -> impl TypedValueParser<Value = AdmissionPolicy> {
    let all = [AdmissionPolicy::Refuse, AdmissionPolicy::AcceptAndWarn];
    PossibleValuesParser::new(all.map(AdmissionPolicy::name)).try_map(move |name| {
        all.into_iter()
            .find(|policy| policy.name() == name)
            .ok_or_else(|| format!("unknown policy {name:?}"))
    })
}

fn sensor_topic_parser() -> impl TypedValueParser<Value = Topic> {
    let sensor_names: Vec<&'static str> = TOPICS
        .iter()
        .filter(|info| info.is_sensor)
        .map(|info| info.name)
        .collect();
    PossibleValuesParser::new(sensor_names)
        .try_map(|name| Topic::from_name(&name).ok_or_else(|| format!("unknown topic {name:?}")))
}

fn parse_timeout(text: &str) -> Result<std::time::Duration, String> {
    crate::period::parse_duration(text).map_err(|error| error.to_string())
}

/// `255,128,0` or `#FF8000`.
pub fn parse_rgb(text: &str) -> Result<Rgb, String> {
    if let Some(hex) = text.strip_prefix('#') {
        return match crate::frame::parse_hex_bytes(hex).as_deref() {
            Some([r, g, b]) => Ok(Rgb {
                r: *r,
                g: *g,
                b: *b,
            }),
            _ => Err(format!(
                "{text:?} is not a colour: write #RRGGBB with hex digits, e.g. #FF8000"
            )),
        };
    }
    let channels: Vec<&str> = text.split(',').map(str::trim).collect();
    let [r, g, b] = channels.as_slice() else {
        return Err(format!(
            "{text:?} is not a colour: write red,green,blue, e.g. 255,128,0"
        ));
    };
    let channel = |name: &str, value: &str| {
        value
            .parse::<u8>()
            .map_err(|_| format!("{name} {value:?} is not a number from 0 to 255"))
    };
    Ok(Rgb {
        r: channel("red", r)?,
        g: channel("green", g)?,
        b: channel("blue", b)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn colours_parse_in_both_forms() {
        assert_eq!(
            parse_rgb("255,128,0"),
            Ok(Rgb {
                r: 255,
                g: 128,
                b: 0
            })
        );
        assert_eq!(parse_rgb(" 1, 2 ,3"), Ok(Rgb { r: 1, g: 2, b: 3 }));
        assert_eq!(
            parse_rgb("#ff8000"),
            Ok(Rgb {
                r: 255,
                g: 128,
                b: 0
            })
        );
        assert!(parse_rgb("256,0,0").is_err());
        assert!(parse_rgb("1,2").is_err());
        assert!(parse_rgb("#FF80").is_err());
        assert!(parse_rgb("red").is_err());
    }
}
