//! DiWheelDrive 1-2's QEMU scenarios (`diwheeldrive/qemu/rev-1-2/*.log`, each its own since 2026-12-06): the BNO055
//! behind the same topics as 1-1.
use anyhow::{ensure, Context, Result};

use super::{diwheeldrive, Bounds, RunOutput, Scenario};

/// Every scenario CI runs on the 1-2 build.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "imu-publishers",
        about: "the five motion topics from the BNO055 on their grids, with the values of a robot at rest in Bielefeld",
        check: imu_publishers,
    },
    Scenario {
        name: "dead-imu",
        about: "the BNO055 stops answering: its topics stop, the floor keeps its grid, the fault is reported; it comes back after the retry",
        check: dead_imu,
    },
    Scenario {
        name: "malformed",
        about: "bad frames are counted and harmless (the gyroscope every 11 ms, stopped before the health one-shot)",
        check: malformed,
    },
    Scenario {
        name: "admission-search",
        about: "issue 20: the costliest command sequence 28 searches found on a 1-2 robot's tables, replayed on the 1-2 image: every step within the admission task's budget per step; the costliest reaches the check's iteration budget per decision",
        check: diwheeldrive::admission_search,
    },
    Scenario {
        name: "flood",
        about: "commands at full bus rate keep an 11 ms gyroscope within its bound",
        check: flood,
    },
];

/// The data of frames `id` in `[from, to)` µs.
fn payloads(out: &RunOutput, id: u32, from: u64, to: u64) -> Vec<&[u8]> {
    out.frames
        .iter()
        .filter(|f| f.id == id && (from..to).contains(&f.at_us))
        .map(|f| f.data.as_slice())
        .collect()
}

fn i16s(data: &[u8]) -> Option<[i16; 3]> {
    let word = |i: usize| Some(i16::from_le_bytes([*data.get(i)?, *data.get(i + 1)?]));
    Some([word(0)?, word(2)?, word(4)?])
}

fn i32_of(data: &[u8]) -> Option<i32> {
    Some(i32::from_le_bytes(data.get(..4)?.try_into().ok()?))
}

fn imu_publishers(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    // One BNO055 topic at a time (a second is refused beside the first at every period and level since the
    // publisher rows are the machine code's, 2026-12-06): each in its own window, from its request to its stop
    // (`diwheeldrive/qemu/rev-1-2/imu-publishers.log`).
    let gyro = out.periodic_stream(0x508, "gyroscope", 12_000, 0, 125_000)?;
    let accel = out.periodic_stream(0x609, "accelerometer", 20_000, 130_000, 330_000)?;
    let mut worst = Vec::new();
    for (stream, topic, level, period) in [
        (&gyro, "gyroscope", "high", 12_000),
        (&accel, "accelerometer", "medium", 20_000),
    ] {
        let bound = bounds.publisher_latency_us(topic, level, period)?;
        ensure!(
            stream.worst_latency <= bound,
            "{topic}: worst latency {} µs above the analysed {bound} µs",
            stream.worst_latency
        );
        worst.push(format!("{topic} {} ≤ {bound} µs", stream.worst_latency));
    }
    let mut axes = [Vec::new(), Vec::new(), Vec::new()];
    for (axis, (id, topic, from, to)) in [
        (0x705, "magnetometer-x", 335_000, 515_000),
        (0x706, "magnetometer-y", 520_000, 700_000),
        (0x707, "magnetometer-z", 705_000, 885_000),
    ]
    .into_iter()
    .enumerate()
    {
        let stream = out.periodic_stream(id, topic, 20_000, from, to)?;
        ensure!(
            stream.frames.len() >= 8,
            "{topic}: only {} frames",
            stream.frames.len()
        );
        let bound = bounds.publisher_latency_us(topic, "low", 20_000)?;
        ensure!(
            stream.worst_latency <= bound,
            "{topic}: worst latency {} µs above the analysed {bound} µs",
            stream.worst_latency
        );
        if axis == 0 {
            worst.push(format!("{topic} {} ≤ {bound} µs", stream.worst_latency));
        }
        axes[axis] = payloads(out, id, 0, to)
            .into_iter()
            .map(|d| i32_of(d).context("magnetometer frame of 4 bytes"))
            .collect::<Result<Vec<i32>>>()?;
    }
    // One topic at a time: no BNO055 frame outside its own window.
    for (id, from, to) in [
        (0x508, 0, 125_000 + 12_000),
        (0x609, 130_000, 330_000 + 20_000),
        (0x705, 335_000, 515_000 + 20_000),
        (0x706, 520_000, 700_000 + 20_000),
        (0x707, 705_000, 885_000 + 20_000),
    ] {
        let outside: Vec<u64> = out
            .times(id)
            .into_iter()
            .filter(|t| !(from..to).contains(t))
            .collect();
        ensure!(
            outside.is_empty(),
            "{id:03X} after its stop or before its request: {outside:?} µs"
        );
    }
    // At rest: below 1 °/s on every axis.
    for data in payloads(out, 0x508, 0, 950_000) {
        let rate = i16s(data).context("gyroscope frame of 6 bytes")?;
        ensure!(
            rate.iter().all(|r| r.abs() <= 1),
            "gyroscope {rate:?} °/s: the robot is at rest"
        );
    }
    // Level: 1 g on Z, nothing on X and Y.
    for data in payloads(out, 0x609, 0, 950_000) {
        let [x, y, z] = i16s(data).context("accelerometer frame of 6 bytes")?;
        ensure!(
            x.abs() <= 20 && y.abs() <= 20 && (980..=1020).contains(&z),
            "accelerometer ({x}, {y}, {z}) mg: the robot stands level"
        );
    }
    // Bielefeld's field: about 49 µT, inclination about 67° (pointing down).
    let n = axes.iter().map(Vec::len).min().unwrap_or(0);
    ensure!(n > 0, "no magnetometer samples");
    for ((x, y), z) in axes[0].iter().zip(&axes[1]).zip(&axes[2]) {
        let [x, y, z] = [*x, *y, *z].map(f64::from);
        let total = (x * x + y * y + z * z).sqrt();
        let inclination = (-z).atan2((x * x + y * y).sqrt()).to_degrees();
        ensure!(
            (47_000.0..=51_000.0).contains(&total) && (65.0..=69.0).contains(&inclination),
            "field ({x}, {y}, {z}) nT: {total:.0} nT at {inclination:.1}°, expected about 49 µT at 67°"
        );
    }
    let health = super::check_health(out, amiro_can::Board::DiWheelDrive)?;
    ensure!(
        health.rejected == 0,
        "{} commands rejected",
        health.rejected
    );
    let refused = out.end_field("admission refused")?;
    ensure!(
        refused == 0,
        "{refused} requests refused: each topic alone, and the health one-shot with nothing running, are admitted"
    );
    Ok(format!(
        "{} gyroscope, {} accelerometer, {n} × 3 magnetometer samples on their grids ({}); values at rest, level, {:.1} µT at the inclination checked",
        gyro.frames.len(),
        accel.frames.len(),
        worst.join(", "),
        {
            let [x, y, z] = [axes[0][0], axes[1][0], axes[2][0]].map(f64::from);
            (x * x + y * y + z * z).sqrt() / 1000.0
        }
    ))
}

/// The Status page's sensor-fault flag and count in the diagnostics sample answered in `[from, to)`.
fn sensor_status(out: &RunOutput, from: u64, to: u64) -> Result<(bool, u32)> {
    use amiro_can::{DiagnosticsPage, Message, SensorData, StatusFlags};
    for f in out
        .frames
        .iter()
        .filter(|f| f.id == 0x61A && (from..to).contains(&f.at_us))
    {
        let id = amiro_can::CanId::try_from(f.id as u16).map_err(|e| anyhow::anyhow!("{e}"))?;
        let frame = amiro_can::Frame::new(id, &f.data).map_err(|e| anyhow::anyhow!("{e}"))?;
        if let Ok(Message::Sample {
            data:
                SensorData::Diagnostics {
                    page:
                        DiagnosticsPage::Status {
                            flags,
                            sensor_faults,
                            ..
                        },
                    ..
                },
            ..
        }) = frame.decode()
        {
            return Ok((
                flags.contains(StatusFlags::SENSOR_FAULT),
                sensor_faults.get(),
            ));
        }
    }
    anyhow::bail!("no diagnostics status page in {from}..{to} µs")
}

/// The shared malformed check on `rev-1-2/malformed.log`: the gyroscope every 11 ms until its stop at 95 ms.
fn malformed(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    diwheeldrive::malformed_with(out, bounds, 11_000, 95_000)
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    diwheeldrive::flood_at(out, bounds, 11_000, super::FLOOD_COMMANDS + 1)
}

fn dead_imu(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    // `rev-1-2/dead-imu.log`: the gyroscope every 12 ms from 5 ms, the part dead at 105 ms, the gyroscope stopped at
    // 150 ms, the floor every 20 ms from 155 to 305 ms with the health asked at 250 ms, the part back at 300 ms, the
    // gyroscope asked again at 310 ms and stopped at 1.35 s, the health asked at 1.355 s. One BNO055 topic, and the
    // health only with none running: since the publisher rows are the machine code's (2026-12-06) the board refuses
    // the health one-shot and the floor beside a BNO055 publisher.
    const PERIOD: u64 = 12_000;
    const RESTART: u64 = 310_000;
    const STOP: u64 = 1_350_000;
    ensure!(
        out.notes
            .iter()
            .any(|n| n.contains("the BNO055 stops answering")),
        "the control frame did not reach the simulated part"
    );
    let before = out.periodic_stream(0x508, "gyroscope", PERIOD, 0, 100_000)?;
    // Nothing invented while the part is dead: no gyroscope frame from 110 ms (one sample in flight at 105 ms may
    // still leave) until the retry, the restarted publisher's releases on their grid all along.
    let dead: Vec<u64> = out
        .frames
        .iter()
        .filter(|f| f.id == 0x508 && (110_000..1_100_000).contains(&f.at_us))
        .map(|f| f.at_us)
        .collect();
    ensure!(
        dead.is_empty(),
        "gyroscope frames while the BNO055 was dead or not yet configured again: {dead:?} µs"
    );
    let restarted = out.releases_on_grid("gyroscope", PERIOD, RESTART, STOP)?;
    // The floor sensors (I2C2) keep their grid while the BNO055 (I2C1) is dead.
    let floor = out.periodic_stream(0x604, "floor-proximity", 20_000, 155_000, 305_000)?;
    let (faulty, faults) = sensor_status(out, 250_000, 260_000)?;
    ensure!(
        faulty && faults >= 3,
        "diagnostics at 250 ms: sensor fault {faulty}, {faults} faults (expected the fault flag and at least 3)"
    );
    // Back after the 1 s back-off (its set-up steps taken a release each): from the release of the first frame on,
    // every release of the second request's grid (checked above) with its frame.
    let resumed = out
        .times(0x508)
        .into_iter()
        .find(|t| *t >= 110_000)
        .context("the gyroscope never resumed")?;
    let from = restarted
        .iter()
        .copied()
        .rfind(|r| *r <= resumed)
        .context("a gyroscope frame before the second request's first release")?;
    let after = out.periodic_stream(0x508, "gyroscope", PERIOD, from, STOP)?;
    ensure!(
        after.frames.len() >= 5,
        "only {} gyroscope samples after the retry",
        after.frames.len()
    );
    let (faulty_after, faults_after) = sensor_status(out, STOP, STOP + 20_000)?;
    ensure!(
        !faulty_after && faults_after >= faults,
        "diagnostics at 1.355 s: sensor fault {faulty_after}, {faults_after} faults (expected the flag clear, the count kept)"
    );
    let refused = out.end_field("admission refused")?;
    ensure!(refused == 0, "{refused} requests refused");
    Ok(format!(
        "{} gyroscope frames, then none while dead; {} floor samples on their 20 ms grid while it was; diagnostics: sensor fault, {faults} faults; the retry brought the gyroscope back at {resumed} µs on the grid of its request at {} µs",
        before.frames.len(),
        floor.frames.len(),
        restarted[0]
    ))
}
