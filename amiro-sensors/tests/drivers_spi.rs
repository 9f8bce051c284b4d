//! Mock-transaction tests of the SPI drivers (L3G4200D gyroscope, LIS331DLH accelerometer):
//! the exact command bytes and register values of set-up, the identity check, data read and
//! conversion, and the error paths.

use amiro_sensors::drivers::l3g4200d::{self, AngularRate, L3g4200d};
use amiro_sensors::drivers::lis331dlh::{self, Acceleration, Lis331dlh};
use amiro_sensors::drivers::Error;
use embedded_hal::spi::{self, ErrorKind, Operation, SpiDevice};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as T};

mod common;
use common::{read_tx, write_tx};

/// An SPI device whose every transfer fails.
struct BrokenSpi;

impl spi::ErrorType for BrokenSpi {
    type Error = ErrorKind;
}

impl SpiDevice for BrokenSpi {
    fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
        Err(ErrorKind::Overrun)
    }
}

// ---------------------------------------------------------------- L3G4200D

const GYRO_CONFIG: [u8; 5] = [0x1F, 0x00, 0x08, 0x10, 0x00];
const ACCEL_CONFIG: [u8; 5] = [0x27, 0x00, 0x82, 0x30, 0x00];

/// What `init` does on either part: WHO_AM_I read (answering `identity`), CTRL_REG1..5 written in
/// one auto-increment burst, then read back in one (answering `readback`).
fn init_script(identity: u8, config: [u8; 5], readback: [u8; 5]) -> Vec<T<u8>> {
    [
        read_tx(0x8F, &[identity]), // WHO_AM_I, read, single byte
        write_tx(0x60, &config),    // CTRL_REG1.., write, auto-increment
        read_tx(0xE0, &readback),   // CTRL_REG1.., read, auto-increment
    ]
    .concat()
}

#[test]
fn gyro_init_writes_the_original_settings_and_reads_them_back() {
    let mut spi = SpiMock::new(&init_script(0xD3, GYRO_CONFIG, GYRO_CONFIG));
    let mut gyro = L3g4200d::new(spi.clone());
    gyro.init().unwrap();
    assert_eq!(gyro.control_registers(), GYRO_CONFIG);
    spi.done();
}

#[test]
fn both_parts_reject_a_wrong_identity_before_writing_anything() {
    let wrong = |expected, found| Err(Error::WrongIdentity { expected, found });
    let mut spi = SpiMock::new(&read_tx(0x8F, &[0xD4]));
    assert_eq!(L3g4200d::new(spi.clone()).init(), wrong(0xD3, 0xD4));
    spi.done();
    let mut spi = SpiMock::new(&read_tx(0x8F, &[0xD3]));
    assert_eq!(Lis331dlh::new(spi.clone()).init(), wrong(0x32, 0xD3));
    spi.done();
}

#[test]
fn both_parts_report_a_register_that_did_not_take_the_range() {
    let mismatch = |expected, found| {
        Err(Error::ConfigMismatch {
            register: 0x23,
            expected,
            found,
        })
    };
    let mut readback = GYRO_CONFIG;
    readback[3] = 0x00; // still ±250 dps
    let mut spi = SpiMock::new(&init_script(0xD3, GYRO_CONFIG, readback));
    assert_eq!(L3g4200d::new(spi.clone()).init(), mismatch(0x10, 0x00));
    spi.done();
    let mut readback = ACCEL_CONFIG;
    readback[3] = 0x10; // still ±4 g
    let mut spi = SpiMock::new(&init_script(0x32, ACCEL_CONFIG, readback));
    assert_eq!(Lis331dlh::new(spi.clone()).init(), mismatch(0x30, 0x10));
    spi.done();
}

#[test]
fn gyro_reads_six_bytes_in_one_burst_and_converts_at_17_5_mdps() {
    // X = 1000 digits, Y = -1000, Z = 32767 (little-endian).
    let raw = [0xE8, 0x03, 0x18, 0xFC, 0xFF, 0x7F];
    let mut spi = SpiMock::new(&read_tx(0xE8, &raw));
    let mut gyro = L3g4200d::new(spi.clone());
    let rate = gyro.read().unwrap();
    assert_eq!(rate.millidegrees_per_s, [17_500, -17_500, 573_423]);
    assert_eq!(rate.degrees_per_s(), [18, -18, 573]);
    spi.done();
}

#[test]
fn gyro_rounds_whole_degrees_to_nearest() {
    // 28 digits = 490 mdps → 0 dps; 29 digits = 507.5 → 508 mdps → 1 dps; -29 → -1.
    let rate = AngularRate::from_raw([28, 29, -29], l3g4200d::Range::Dps500);
    assert_eq!(rate.millidegrees_per_s, [490, 508, -508]);
    assert_eq!(rate.degrees_per_s(), [0, 1, -1]);
}

#[test]
fn gyro_ranges_have_the_datasheet_sensitivities_and_ctrl4_bits() {
    use l3g4200d::Range;
    assert_eq!(
        AngularRate::from_raw([1000, 0, 0], Range::Dps250).millidegrees_per_s[0],
        8_750
    );
    assert_eq!(
        AngularRate::from_raw([1000, 0, 0], Range::Dps2000).millidegrees_per_s[0],
        70_000
    );
    assert_eq!(
        [Range::Dps250, Range::Dps500, Range::Dps2000].map(Range::ctrl_reg4),
        [0x00, 0x10, 0x20]
    );
}

#[test]
fn gyro_sleep_and_wake_write_ctrl_reg1_only() {
    let script = [write_tx(0x20, &[0x18]), write_tx(0x20, &[0x1F])].concat();
    let mut spi = SpiMock::new(&script);
    let mut gyro = L3g4200d::new(spi.clone());
    gyro.sleep().unwrap();
    gyro.wake().unwrap();
    spi.done();
}

#[test]
fn gyro_passes_bus_errors_through() {
    let mut gyro = L3g4200d::new(BrokenSpi);
    assert_eq!(gyro.init(), Err(Error::Bus(ErrorKind::Overrun)));
    assert_eq!(gyro.read(), Err(Error::Bus(ErrorKind::Overrun)));
}

// ---------------------------------------------------------------- LIS331DLH

#[test]
fn accel_init_writes_the_original_settings_at_8g() {
    let mut spi = SpiMock::new(&init_script(0x32, ACCEL_CONFIG, ACCEL_CONFIG));
    let mut accel = Lis331dlh::new(spi.clone());
    accel.init().unwrap();
    spi.done();
}

#[test]
fn accel_at_4g_writes_the_1x_ctrl4() {
    let config = [0x27, 0x00, 0x82, 0x10, 0x00];
    let mut spi = SpiMock::new(&init_script(0x32, config, config));
    let mut accel = Lis331dlh::with_range(spi.clone(), lis331dlh::Range::G4);
    accel.init().unwrap();
    spi.done();
}

#[test]
fn accel_ignores_the_self_clearing_boot_bit_on_read_back() {
    let mut readback = ACCEL_CONFIG;
    readback[1] = 0x80; // BOOT still showing: not a mismatch
    let mut spi = SpiMock::new(&init_script(0x32, ACCEL_CONFIG, readback));
    Lis331dlh::new(spi.clone()).init().unwrap();
    spi.done();
}

#[test]
fn accel_converts_left_justified_12_bit_at_3_9_mg_per_digit() {
    // X = 256 digits << 4 = 4096 (+ noise in the low nibble), Y = -256 << 4, Z = 2047 << 4.
    let x = 4096i16 + 0x0F;
    let y = -4096i16;
    let z = 2047i16 << 4;
    let raw: Vec<u8> = [x, y, z].iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut spi = SpiMock::new(&read_tx(0xE8, &raw));
    let mut accel = Lis331dlh::new(spi.clone());
    let a = accel.read().unwrap();
    assert_eq!(a.micro_g, [998_400, -998_400, 7_983_300]);
    assert_eq!(a.milli_g(), [998, -998, 7_983]);
    spi.done();
}

#[test]
fn accel_ranges_scale_the_same_raw_value() {
    use lis331dlh::Range;
    let raw = [1000 << 4, 0, 0];
    assert_eq!(Acceleration::from_raw(raw, Range::G2).milli_g()[0], 1000);
    assert_eq!(Acceleration::from_raw(raw, Range::G4).milli_g()[0], 2000);
    assert_eq!(Acceleration::from_raw(raw, Range::G8).milli_g()[0], 3900);
}

#[test]
fn accel_power_down_and_bus_errors() {
    let mut spi = SpiMock::new(&write_tx(0x20, &[0x00]));
    Lis331dlh::new(spi.clone()).power_down().unwrap();
    spi.done();
    let mut broken = Lis331dlh::new(BrokenSpi);
    assert_eq!(broken.read(), Err(Error::Bus(ErrorKind::Overrun)));
    assert_eq!(broken.check_identity(), Err(Error::Bus(ErrorKind::Overrun)));
}

/// The conversions' 64-bit definition: `n / d` rounded to nearest, halves away from zero.
fn rounded(n: i64, d: i64) -> i64 {
    if n >= 0 {
        (n + d / 2) / d
    } else {
        (n - d / 2) / d
    }
}

/// The protocol's saturation to `i16`.
fn saturated(v: i64) -> i16 {
    v.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16
}

#[test]
fn gyro_conversions_in_32_bits_equal_the_64_bit_definition_for_every_reading() {
    for range in [
        l3g4200d::Range::Dps250,
        l3g4200d::Range::Dps500,
        l3g4200d::Range::Dps2000,
    ] {
        let s = i64::from(range.micro_dps_per_digit());
        for raw in i16::MIN..=i16::MAX {
            let expected_m = rounded(i64::from(raw) * s, 1000);
            let rate = AngularRate::from_raw([raw, 0, raw], range);
            assert_eq!(
                rate.millidegrees_per_s,
                [expected_m as i32, 0, expected_m as i32],
                "{range:?} {raw}"
            );
            assert_eq!(
                rate.degrees_per_s()[0],
                saturated(rounded(expected_m, 1000)),
                "{range:?} {raw}"
            );
        }
    }
}

#[test]
fn accel_milli_g_in_32_bits_equals_the_64_bit_definition_for_every_reading() {
    for range in [
        lis331dlh::Range::G2,
        lis331dlh::Range::G4,
        lis331dlh::Range::G8,
    ] {
        for raw in i16::MIN..=i16::MAX {
            let a = Acceleration::from_raw([raw, 0, 0], range);
            assert_eq!(
                a.milli_g()[0],
                saturated(rounded(i64::from(a.micro_g[0]), 1000)),
                "{range:?} {raw}"
            );
        }
    }
}

/// The public structs hold any i32: the conversions to the protocol's units saturate at both ends
/// of i16 without overflowing on the way (the rounding offset near i32::MAX and i32::MIN), and
/// agree with rounding in 64 bits then saturating.
#[test]
fn conversions_saturate_at_the_i32_extremes_without_overflow() {
    let wide = |value: i32| {
        let v = i64::from(value);
        let q = if v >= 0 {
            (v + 500) / 1000
        } else {
            (v - 500) / 1000
        };
        q.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16
    };
    let extremes = [
        i32::MAX,
        i32::MAX - 1,
        i32::MAX - 499,
        i32::MAX - 500,
        i32::MIN,
        i32::MIN + 1,
        i32::MIN + 499,
        i32::MIN + 500,
        32_767_499,
        32_767_500,
        -32_768_499,
        -32_768_500,
        -1_500,
        1_499,
        0,
    ];
    for value in extremes {
        let rate = AngularRate {
            millidegrees_per_s: [value, value, value],
        };
        let acceleration = Acceleration {
            micro_g: [value, value, value],
        };
        assert_eq!(rate.degrees_per_s(), [wide(value); 3], "{value} mdps");
        assert_eq!(acceleration.milli_g(), [wide(value); 3], "{value} µg");
    }
    let rate = AngularRate {
        millidegrees_per_s: [i32::MAX, i32::MIN, -1_500],
    };
    assert_eq!(rate.degrees_per_s(), [i16::MAX, i16::MIN, -2]);
}
