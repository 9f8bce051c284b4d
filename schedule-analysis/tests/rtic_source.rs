//! The RTIC source reader on fixture apps: the DiWheelDrive fallback description, an app with `extern` task
//! declarations, `idle`, `#[lock_free]` and `cfg`, and sources it must refuse.

use std::path::Path;

use schedule_analysis::rtic_source::{parse_app, RticTaskKind};

fn fixture() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/diwheeldrive.fallback-app.rs");
    std::fs::read_to_string(path).expect("the fallback app exists")
}

#[test]
fn reads_the_diwheeldrive_task_list() {
    let app = parse_app(&fixture()).expect("parses").with_features(&[]);
    assert_eq!(app.device.as_deref(), Some("stm32f1xx_hal::pac"));
    assert_eq!(
        app.dispatchers,
        ["UART4", "UART5", "TIM6", "TIM7", "SDIO", "DMA2_CHANNEL1"]
    );
    let shared: Vec<&str> = app.shared.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        shared,
        ["handler", "tx_queue", "drive", "imu", "compass", "floor", "alive"]
    );

    let summary: Vec<(&str, u8, bool)> = app
        .tasks
        .iter()
        .map(|t| {
            (
                t.name.as_str(),
                t.priority,
                matches!(t.kind, RticTaskKind::Hardware { .. }),
            )
        })
        .collect();
    assert_eq!(
        summary,
        [
            ("can_rx", 6, true),
            ("can_tx", 6, true),
            ("handle_commands", 5, false),
            ("admit_requests", 0, false),
            ("motor_control", 5, false),
            ("publish_urgent", 4, false),
            ("publish_high", 3, false),
            ("publish_medium", 2, false),
            ("publish_low", 1, false),
            ("watchdog", 1, false),
            ("shutdown", 7, true),
            ("shutdown_sequence", 5, false),
        ]
    );
    let can_rx = app.task("can_rx").expect("can_rx");
    assert_eq!(
        can_rx.kind,
        RticTaskKind::Hardware {
            binds: "USB_LP_CAN_RX0".into()
        }
    );
    assert!(can_rx.shared.is_empty());
    assert_eq!(can_rx.local, ["can_rx", "rx_frames"]);
    let publish_high = app.task("publish_high").expect("publish_high");
    assert_eq!(
        publish_high.shared,
        ["handler", "tx_queue", "drive", "imu", "compass", "floor"]
    );
    assert!(publish_high.is_async);
    assert!(
        app.task("stimulus").is_none(),
        "the QEMU-only task is not in the hardware build"
    );
}

#[test]
fn cfg_features_select_tasks() {
    let app = parse_app(&fixture()).expect("parses");
    let qemu = app.with_features(&["qemu"]);
    let stimulus = qemu
        .task("stimulus")
        .expect("the QEMU build has the stimulus task");
    assert_eq!(stimulus.priority, 7);
    assert_eq!(stimulus.cfg, ["feature = \"qemu\""]);
}

const EXTERN_APP: &str = r#"
use rtic::app;

#[app(device = lm3s6965, dispatchers = [SSI0, QEI0])]
mod app {
    #[shared]
    struct Shared {
        counter: u32,
        #[lock_free]
        scratch: [u8; 4],
        #[cfg(feature = "extra")]
        extra: u8,
    }

    #[local]
    struct Local {
        led: Led,
    }

    #[init]
    fn init(_: init::Context) -> (Shared, Local) {
        loop {}
    }

    #[idle(shared = [counter])]
    fn idle(_: idle::Context) -> ! {
        loop {}
    }

    extern "Rust" {
        #[task(binds = UART0, priority = 3, shared = [counter, scratch], local = [led, buf: heapless::Vec<u8, 4> = heapless::Vec::new()])]
        fn uart0(_: uart0::Context);

        #[task(shared = [&counter])]
        async fn background(_: background::Context);
    }
}
"#;

#[test]
fn extern_declarations_idle_lock_free_and_defaults() {
    let app = parse_app(EXTERN_APP).expect("parses");
    assert_eq!(app.dispatchers, ["SSI0", "QEI0"]);
    let idle = app.idle.as_ref().expect("idle");
    assert_eq!(
        (idle.priority, idle.shared.as_slice()),
        (0, ["counter".to_string()].as_slice())
    );
    let uart0 = app.task("uart0").expect("uart0");
    assert_eq!(
        uart0.kind,
        RticTaskKind::Hardware {
            binds: "UART0".into()
        }
    );
    assert_eq!(uart0.priority, 3);
    // The generic type's comma does not split the local list.
    assert_eq!(uart0.local, ["led", "buf"]);
    assert!(uart0.line > 1, "a real line number: {}", uart0.line);
    let background = app.task("background").expect("background");
    assert_eq!(background.priority, 1, "RTIC's default priority");
    assert!(background.is_async);
    assert_eq!(background.shared, ["counter"]);
    assert!(app.is_lock_free("scratch"));
    assert!(!app.is_lock_free("counter"));
    assert_eq!(app.shared.len(), 3);
    assert_eq!(app.with_features(&[]).shared.len(), 2);
}

#[test]
fn refuses_what_is_not_an_rtic_app() {
    let not_rust = parse_app("fn main( {").expect_err("not Rust");
    assert!(not_rust.message.contains("not valid Rust"), "{not_rust}");
    let no_app = parse_app("mod app { fn f() {} }").expect_err("no app");
    assert!(no_app.message.contains("#[rtic::app]"), "{no_app}");
    let unknown = parse_app(
        "#[rtic::app(device = x)]\nmod app {\n    #[shared]\n    struct Shared { a: u8 }\n    #[task(priority = 2, shared = [b])]\n    async fn t(_: t::Context) {}\n}\n",
    )
    .expect_err("unknown resource");
    assert!(
        unknown.message.contains("`b`") && unknown.line == 6,
        "{unknown}"
    );
    let bad_priority = parse_app("#[rtic::app(device = x)]\nmod app {\n    #[task(priority = high)]\n    async fn t(_: t::Context) {}\n}\n")
        .expect_err("bad priority");
    assert!(
        bad_priority.message.contains("priority `high`"),
        "{bad_priority}"
    );
}
