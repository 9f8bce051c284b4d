//! The power master's decisions, free of pins: when the chargers may run, what the power-status
//! frame says about two batteries (from the power monitor's latest gauge round), and when the
//! battery is too low to go on.
//!
//! The board (`board.rs`, or `qemu.rs`) reads the lines and the gauges and applies the answers;
//! docs/boards.md ("PowerManagement") explains each rule.
use amiro_can::{PowerStatus, ShutdownMode};
use amiro_sensors::drivers::bq27500::{BatteryStatus, Flags, PowerSummary, TIME_NOT_APPLICABLE};

/// The chargers may run only while VSYS is above this (reference §5, §7: "> 9 V").
pub const CHARGE_ON_ABOVE_MV: u32 = 9_000;
/// Once running, they stop again below this (200 mV hysteresis, so a sagging supply does not
/// toggle them every period).
pub const CHARGE_OFF_BELOW_MV: u32 = 8_800;
/// The VSYS divider on PB1 (reference §5: ≈ 5.33), as a ratio of integers.
pub const VSYS_DIVIDER: (u32, u32) = (533, 100);
/// ADC reference (VDDA) in mV and full scale of the 12-bit conversion.
pub const ADC_VREF_MV: u32 = 3_300;
/// Full scale of a 12-bit conversion.
pub const ADC_FULL_SCALE: u32 = 4_095;
/// Below this combined state of charge (%), without the charger, the robot shuts down.
pub const CRITICAL_STATE_OF_CHARGE: u8 = 3;
/// The shutdown a critically low battery causes: hibernate, which the charger wakes from.
pub const LOW_BATTERY_MODE: ShutdownMode = ShutdownMode::Hibernate;

/// VSYS in mV from a raw 12-bit conversion of the divided voltage.
pub const fn vsys_mv(raw: u16) -> u32 {
    let pin_mv = raw as u32 * ADC_VREF_MV / ADC_FULL_SCALE;
    pin_mv * VSYS_DIVIDER.0 / VSYS_DIVIDER.1
}

/// Whether the chargers should run, given VSYS (`None`: the conversion failed) and whether they
/// run now. Unknown VSYS means off: charging is the one thing this board must not do blindly.
pub const fn charging_allowed(vsys_mv: Option<u32>, enabled: bool) -> bool {
    match vsys_mv {
        Some(mv) if enabled => mv >= CHARGE_OFF_BELOW_MV,
        Some(mv) => mv > CHARGE_ON_ABOVE_MV,
        None => false,
    }
}

/// The charge-related input lines and the chargers' enable state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChargeLines {
    /// PATH_DC: the power plug is in.
    pub plug: bool,
    /// The chargers are enabled (EN1_N / EN2_N low).
    pub enabled: bool,
    /// STAT1A (front) and STAT2A (rear): the bq24103A reports charging.
    pub stat: [bool; 2],
}

impl ChargeLines {
    /// The robot is charging: plug in, chargers enabled, and at least one charger says so.
    pub const fn charging(&self) -> bool {
        self.plug && self.enabled && (self.stat[0] || self.stat[1])
    }
}

/// Both fuel gauges' statuses from the power monitor's latest round, the only place the gauges
/// are read (docs/boards.md, "PowerManagement": the power-status sample's age): a gauge whose read
/// failed in that round is `None` (its failure counted in the bus's diagnostics when it happened),
/// and so is each gauge before the boot's round has ended. No time stamp: the schedule bounds the
/// age (a round of at most 26 power monitor periods, a transfer each), and a power
/// monitor that stops leaves the watchdog unfed, which resets the board.
#[derive(Debug, Clone, Copy, Default)]
pub struct LatestRound {
    front: Option<BatteryStatus>,
    rear: Option<BatteryStatus>,
}

impl LatestRound {
    /// No round yet: the power-status sample has no frame until the first one ends.
    pub const fn new() -> Self {
        Self {
            front: None,
            rear: None,
        }
    }

    /// One gauge's read (`rear`: the rear gauge's, else the front one's) replaces its last status,
    /// a failed read's `None` included.
    pub fn record(&mut self, rear: bool, status: Option<BatteryStatus>) {
        if rear {
            self.rear = status;
        } else {
            self.front = status;
        }
    }

    /// [`critically_low`] with the latest statuses.
    pub fn critically_low(&self, lines: &ChargeLines) -> bool {
        critically_low(self.front.as_ref(), self.rear.as_ref(), lines)
    }

    /// The power-status frame ([`status`]) from the latest statuses and the charge lines read
    /// now: `None` (no frame) when neither gauge answered in the latest round or no round has
    /// ended yet.
    pub fn status(&self, lines: &ChargeLines) -> Option<PowerStatus> {
        status(self.front.as_ref(), self.rear.as_ref(), lines)
    }
}

/// The power-status frame from both gauges (either may be missing) and the charge lines; `None`
/// when neither gauge answered (the sample then has no frame).
///
/// Two batteries become one frame: charging comes from the lines (not from the gauges' current
/// sign, which a nearly full pack blurs); the state of charge is remaining over full capacity of
/// both packs; minutes are the later of the two estimates that apply (the robot runs until the
/// last pack is empty, and is full when the last pack is full); power is the sum.
pub fn status(
    front: Option<&BatteryStatus>,
    rear: Option<&BatteryStatus>,
    lines: &ChargeLines,
) -> Option<PowerStatus> {
    let summary = match (front, rear) {
        (Some(a), Some(b)) => PowerSummary::of_pair(a, b),
        (Some(one), None) | (None, Some(one)) => PowerSummary::of(one),
        (None, None) => return None,
    };
    let charging = lines.charging();
    let estimate = |s: &BatteryStatus| {
        if charging {
            s.time_to_full_min
        } else {
            s.time_to_empty_min
        }
    };
    let minutes = front
        .and_then(estimate)
        .into_iter()
        .chain(rear.and_then(estimate))
        .max()
        .unwrap_or(TIME_NOT_APPLICABLE);
    Some(PowerStatus {
        charging,
        state_of_charge: summary.state_of_charge,
        minutes,
        power_mw: summary.power_mw,
    })
}

/// Whether the battery is critically low: not on the charger, at least one gauge answered, and
/// either the combined state of charge is at most [`CRITICAL_STATE_OF_CHARGE`] or every gauge that
/// answered has raised its final-discharge flag (SOCF).
pub fn critically_low(
    front: Option<&BatteryStatus>,
    rear: Option<&BatteryStatus>,
    lines: &ChargeLines,
) -> bool {
    if lines.plug {
        return false;
    }
    let Some(status) = status(front, rear, lines) else {
        return false;
    };
    let final_flag =
        |s: Option<&BatteryStatus>| s.is_none_or(|s| s.flags.contains(Flags::SOC_FINAL));
    status.state_of_charge <= CRITICAL_STATE_OF_CHARGE || (final_flag(front) && final_flag(rear))
}

/// The AMiRo-BLT callback that enters `mode` (reference §2: the callback table).
pub const fn callback(mode: ShutdownMode) -> amiro_firmware::bootloader::Callback {
    use amiro_firmware::bootloader::Callback;
    match mode {
        ShutdownMode::Hibernate => Callback::Hibernate,
        ShutdownMode::DeepSleep => Callback::DeepSleep,
        ShutdownMode::Transportation => Callback::Transportation,
        ShutdownMode::Restart => Callback::Restart,
    }
}

/// One VSYS check: the chargers follow [`charging_allowed`]; a change is logged.
pub fn regulate_charging(charger: &mut crate::platform::Charger) {
    let vsys = charger.vsys_mv();
    let on = charging_allowed(vsys, charger.enabled());
    if on != charger.enabled() {
        charger.set_enabled(on);
        let mut digits = [0u8; 10];
        amiro_firmware::log!(
            "chargers ",
            if on { "enabled" } else { "disabled" },
            " (VSYS ",
            amiro_firmware::telemetry::decimal(vsys.unwrap_or(0), &mut digits),
            " mV)"
        );
    }
}
