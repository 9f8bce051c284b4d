//! The admission check's cost on the host: replays a `candump -l` stimulus (a QEMU scenario's log) through a
//! board's [`Admission`] step by step, as the admission task runs them ([`Admission::replay`]), and prints each
//! command's analysed steps with their fixed-point iterations. Run under
//! `valgrind --tool=callgrind` to see where the instructions go.
//!
//! `cargo run --release -p amiro-firmware --example admission_cost -- diwheeldrive/qemu/admission-cost.log`
use amiro_firmware::admission::{Admission, Check, State};
use schedule_analysis::admission_host;

fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let path = std::env::args().nth(1).expect("a stimulus log");
    let board = match std::env::args().nth(2).as_deref() {
        Some("powermgmt") => amiro_can::Board::PowerManagement,
        Some("lightring") => amiro_can::Board::LightRing,
        _ => amiro_can::Board::DiWheelDrive,
    };
    let robot = admission_host::lower_robot(&root).expect("table");
    let text = std::fs::read_to_string(&path).expect("log");
    robot.with_table(|table| {
        let mut state = Box::new(State::<48, 32>::new());
        let mut admission = Admission::new(table, board, &mut state);
        admission.prepare();
        println!(
            "prepare: the costliest step {} iterations",
            admission.iterations().1
        );
        for line in text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        {
            let frame = line.split_whitespace().nth(2).expect("id#data");
            let (id, data) = frame.split_once('#').expect("#");
            let id = u16::from_str_radix(id, 16).expect("id");
            let data: Vec<u8> = (0..data.len() / 2)
                .map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).expect("hex"))
                .collect();
            let mut steps = Vec::new();
            let check = admission.replay(id, &data, |_, iterations| steps.push(iterations));
            let what = match check {
                Check::Pass => "pass",
                Check::Refused(..) => "refused",
                Check::Warned(..) => "warned",
            };
            if !steps.is_empty() {
                println!("{line}: {what}, steps of {steps:?} iterations");
            }
            if let Check::Refused(frames, reason) | Check::Warned(frames, reason) = check {
                println!("    {reason:?} {:?}", frames.map(|f| f.data().to_vec()));
            }
        }
    });
}
