//! The simulators fed from outside (a world's readings, docs/world.md): the real drivers read the
//! fed values, encoded exactly as the patterns are, and `None` gives the pattern back.

use amiro_sensors::drivers::bno055::Bno055;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::hmc5883l::Hmc5883l;
use amiro_sensors::drivers::l3g4200d::L3g4200d;
use amiro_sensors::drivers::lis331dlh::Lis331dlh;
use amiro_sensors::sim::*;

#[test]
fn the_gyroscope_reads_a_fed_turn() {
    let mut gyro = L3g4200d::new(SimGyroscope::new());
    gyro.init().unwrap();
    // 180 °/s about z: 10 285.7 digits of 17.5 mdps at ±500 dps, rounded to 10 286 → 180 005 mdps;
    // −1 °/s on y: −57.1 → −57 digits → −997.5, which the driver rounds away from zero.
    gyro.bus_mut().set_measured(Some([0, -1_000, 180_000]));
    assert_eq!(gyro.read_raw().unwrap(), [0, -57, 10_286]);
    assert_eq!(gyro.read().unwrap().millidegrees_per_s, [0, -998, 180_005]);
    gyro.bus_mut().set_measured(None);
    let rate = gyro.read().unwrap().millidegrees_per_s;
    // Sample 2 of the pattern: the two fed reads counted as samples too.
    let want = SimGyroscope::pattern_at(2);
    assert!(
        rate.iter().zip(want).all(|(g, w)| (g - w).abs() <= 9),
        "{rate:?}"
    );
}

#[test]
fn the_accelerometer_reads_a_fed_acceleration() {
    let mut accel = Lis331dlh::new(SimAccelerometer::new());
    accel.init().unwrap();
    // 0.2 g forward, gravity: 51.3 and 256.4 digits of 3.9 mg at ±8 g → 51, 256 → 198.9, 998.4 mg.
    accel.bus_mut().set_measured(Some([200_000, 0, 1_000_000]));
    assert_eq!(accel.read().unwrap().milli_g(), [199, 0, 998]);
    accel.bus_mut().set_measured(None);
    assert_ne!(accel.read().unwrap().milli_g(), [199, 0, 998]);
}

#[test]
fn the_compass_reads_a_fed_field() {
    let mut compass = Hmc5883l::new(SimCompassBus::new());
    compass.init().unwrap();
    // 19 146 nT north on −y (heading +x with north along +y means north is to the left: +y);
    // 256.4 nT per digit at 390 LSB/Ga: 74.67 → 75 digits, 175.9 → 176.
    compass
        .bus_mut()
        .magnetometer_mut()
        .set_field(Some([0, 19_146, -45_105]));
    let field = compass.read().unwrap().nanotesla;
    assert_eq!(field, [0, 19_231, -45_128]);
}

#[test]
fn the_bno055_reads_a_fed_motion() {
    let mut bus = SimImuBus::new();
    Bno055::new(&mut bus).init(&mut NoDelay).unwrap();
    bus.imu_mut().set_motion(Some(Bno055Motion {
        accel_mg: [20, -5, 1000],
        field_nt: [13_538, -13_538, -45_105],
        rate_digits: [0, 0, 2880],
    }));
    let m = Bno055::new(&mut bus).read().unwrap();
    assert_eq!(m.milli_g, [20, -5, 1000]);
    assert_eq!(m.degrees_per_s, [0, 0, 180]);
    // 1/16 µT digits: 216.6 → 217 = 13 562.5 nT, rounded by the driver to 13 563.
    assert_eq!(m.nanotesla, [13_563, -13_563, -45_125]);
    // A system reset keeps the feed: the world does not reset with the part.
    {
        use embedded_hal::i2c::I2c;
        bus.write(0x28, &[0x3F, 0x20]).unwrap();
    }
    Bno055::new(&mut bus).init(&mut NoDelay).unwrap();
    assert_eq!(
        Bno055::new(&mut bus).read().unwrap().milli_g,
        [20, -5, 1000]
    );
    bus.imu_mut().set_motion(None);
    let (accel, _, _) = SimBno055::physical_at(bus.imu().samples());
    assert_eq!(
        Bno055::new(&mut bus).read().unwrap().milli_g.map(i32::from),
        accel
    );
}

#[test]
fn floor_sensors_read_fed_counts_by_channel() {
    let mut bus = SimFloorBus::new();
    assert!(bus.proximity_mut().set_proximity(0, Some(5_867)));
    assert!(bus.proximity_mut().set_proximity(3, Some(37_643)));
    assert!(
        !bus.proximity_mut().set_proximity(4, Some(1)),
        "four channels"
    );
    let mut floor = FloorSensors::new(&mut bus);
    floor.init().unwrap();
    let counts = floor.read_proximity().unwrap();
    assert_eq!(counts[0], 5_867);
    assert_eq!(counts[3], 37_643);
    // Channels 1 and 2 still read their pattern (sample 0).
    assert_eq!(counts[1], SimVcnl4020::proximity_at(1, 0));
    assert_eq!(counts[2], SimVcnl4020::proximity_at(2, 0));
}

#[test]
fn the_ring_reads_fed_counts_by_protocol_index_across_both_buses() {
    use amiro_sensors::drivers::ring::ProximityRing;
    // Index k gets 2000 + 1e6 / (20 + 10 k)² counts: 20 mm, 30 mm, … 90 mm on the default
    // calibration, whichever bus and channel the index is wired to.
    let counts: [u16; 8] = core::array::from_fn(|k| {
        let mm = 20 + 10 * k as u32;
        (2000 + 1_000_000 / (mm * mm)) as u16
    });
    let mut i2c1 = SimPowerBus::new(0, false);
    let mut i2c2 = SimPowerBus::new(4, false);
    feed_ring(&mut i2c1.target.0, &mut i2c2.target.0, Some(counts));
    {
        let mut ring = ProximityRing::new(&mut i2c1, &mut i2c2);
        ring.init().unwrap();
        assert_eq!(ring.read_counts().unwrap(), counts);
        assert_eq!(ring.read_mm().unwrap(), [20, 30, 40, 50, 60, 70, 80, 90]);
    }
    feed_ring(&mut i2c1.target.0, &mut i2c2.target.0, None);
    let mut ring = ProximityRing::new(&mut i2c1, &mut i2c2);
    assert_ne!(ring.read_counts().unwrap(), counts, "the patterns are back");
}

#[test]
fn feed_floor_follows_the_protocol_order() {
    let mut bus = SimFloorBus::new();
    feed_floor(bus.proximity_mut(), Some([1, 2, 3, 4]));
    let mut floor = FloorSensors::new(&mut bus);
    floor.init().unwrap();
    assert_eq!(floor.read_proximity().unwrap(), [1, 2, 3, 4]);
}
