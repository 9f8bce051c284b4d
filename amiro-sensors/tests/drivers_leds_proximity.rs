//! TLC5947 frame layout and gamma table, and the proximity counts → mm model.

use amiro_sensors::drivers::proximity::{isqrt, ProximityCalibration};
use amiro_sensors::drivers::tlc5947::{self, pack_frame, LightRing, Tlc5947, GAMMA};
use amiro_sensors::drivers::Error;
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as T};
use proptest::prelude::*;

fn frame_tx(frame: Vec<u8>) -> Vec<T<u8>> {
    vec![
        T::transaction_start(),
        T::write_vec(frame),
        T::transaction_end(),
    ]
}

#[test]
fn frame_starts_with_out23_msb_first() {
    let mut channels = [0u16; 24];
    channels[23] = 0xABC;
    channels[22] = 0x123;
    channels[1] = 0x456;
    channels[0] = 0x789;
    let frame = pack_frame(&channels);
    assert_eq!(frame.len(), 36);
    assert_eq!(frame[..3], [0xAB, 0xC1, 0x23]);
    assert_eq!(frame[33..], [0x45, 0x67, 0x89]);
    assert!(frame[3..33].iter().all(|&b| b == 0));
}

#[test]
fn flush_is_one_36_byte_write_latched_by_the_chip_select() {
    let mut expected = vec![0u8; 36];
    expected[35] = 0xFF; // OUT0 = 0x0FF
    expected[34] = 0x00;
    let mut spi = SpiMock::new(&frame_tx(expected));
    let mut driver = Tlc5947::new(spi.clone());
    driver.set_channel(0, 0x0FF).unwrap();
    driver.flush().unwrap();
    spi.done();
}

#[test]
fn channel_values_are_clamped_and_checked() {
    let mut driver = Tlc5947::new(SpiMock::<u8>::new(&[]));
    driver.set_channel(5, 9_999).unwrap();
    assert_eq!(driver.channels()[5], 4095);
    assert_eq!(
        driver.set_channel(24, 1),
        Err(Error::OutOfRange { value: 24, max: 23 })
    );
    driver.release().done();
}

#[test]
fn led_numbers_map_to_output_triples_as_wired() {
    assert_eq!(tlc5947::led_outputs(1), Some([21, 22, 23])); // front-right, NNE
    assert_eq!(tlc5947::led_outputs(4), Some([12, 13, 14])); // rear-right, SSE
    assert_eq!(tlc5947::led_outputs(8), Some([0, 1, 2])); // front-left, NNW
    assert_eq!(tlc5947::led_outputs(0), None);
    assert_eq!(tlc5947::led_outputs(9), None);
}

#[test]
fn set_led_writes_gamma_corrected_rgb_in_red_green_blue_order() {
    let mut channels = [0u16; 24];
    channels[3] = GAMMA[200]; // LED 7 = triple 1: OUT3 red
    channels[4] = GAMMA[100];
    channels[5] = GAMMA[50];
    let mut spi = SpiMock::new(&frame_tx(pack_frame(&channels).to_vec()));
    let mut ring = LightRing::new(spi.clone());
    ring.set_led(7, 200, 100, 50).unwrap();
    ring.flush().unwrap();
    assert_eq!(
        ring.set_led(9, 1, 1, 1),
        Err(Error::OutOfRange { value: 9, max: 8 })
    );
    spi.done();
}

#[test]
fn gamma_table_is_cie_lightness() {
    assert_eq!(GAMMA[0], 0);
    assert_eq!(GAMMA[255], 4095);
    assert!(GAMMA.windows(2).all(|w| w[0] <= w[1]), "monotone");
    assert!(
        GAMMA[1..].iter().all(|&v| v > 0),
        "every non-zero input lights"
    );
    // Input 128 is L* = 50.2, 18.6 % luminance.
    assert_eq!(GAMMA[128], 761);
    // Compare with the formula in floating point.
    for (v, &out) in GAMMA.iter().enumerate() {
        let l = v as f64 * 100.0 / 255.0;
        let y = if l <= 8.0 {
            l / 903.2963
        } else {
            ((l + 16.0) / 116.0).powi(3)
        };
        assert!((y * 4095.0 - f64::from(out)).abs() <= 0.5 + 1e-6, "{v}");
    }
}

// ---------------------------------------------------------------- counts → mm

#[test]
fn default_model_gives_the_documented_distances() {
    let cal = ProximityCalibration::DEFAULT;
    assert_eq!(
        cal.counts_to_mm(2_000),
        200,
        "offset only: nothing in range"
    );
    assert_eq!(cal.counts_to_mm(0), 200);
    assert_eq!(cal.counts_to_mm(2_000 + 100), 100);
    assert_eq!(cal.counts_to_mm(2_000 + 10_000), 10);
    assert_eq!(
        cal.counts_to_mm(2_000 + 10),
        200,
        "beyond range clamps to max"
    );
    assert_eq!(cal.counts_to_mm(u16::MAX), 3);
}

#[test]
fn calibration_from_a_reference_reproduces_the_reference() {
    let cal = ProximityCalibration::from_reference(2_300, 4_800, 40).unwrap();
    assert_eq!(cal.offset, 2_300);
    assert_eq!(cal.k_counts_mm2, 2_500 * 1_600);
    assert_eq!(cal.counts_to_mm(4_800), 40);
    assert_eq!(ProximityCalibration::from_reference(2_300, 2_300, 40), None);
    assert_eq!(ProximityCalibration::from_reference(2_300, 3_000, 0), None);
}

proptest! {
    #[test]
    fn counts_to_mm_is_monotone_and_in_range(
        a in any::<u16>(), b in any::<u16>(), offset in 0u16..5000,
        k in 1u32..50_000_000, min in 0u16..10, max in 50u16..500,
    ) {
        let cal = ProximityCalibration { offset, k_counts_mm2: k, min_mm: min, max_mm: max };
        let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
        prop_assert!(cal.counts_to_mm(hi) <= cal.counts_to_mm(lo));
        let mm = cal.counts_to_mm(a);
        prop_assert!(mm >= min && mm <= max);
    }

    #[test]
    fn isqrt_is_the_floor_square_root(n in any::<u32>()) {
        let r = u64::from(isqrt(n));
        prop_assert!(r * r <= u64::from(n));
        prop_assert!((r + 1) * (r + 1) > u64::from(n));
    }
}
