//! TLC5947 frame layout (one part and a chain of three), the two rings' LED mappings, the gamma
//! table, and the proximity counts → mm model.

use amiro_sensors::drivers::proximity::{isqrt, ProximityCalibration};
use amiro_sensors::drivers::tlc5947::{
    self, led_triples, pack_chain, pack_frame, LightRing, LightRing24, Tlc5947, Tlc5947Chain, GAMMA,
};
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
    assert_eq!(driver.channel(5), Some(4095));
    assert_eq!(driver.channel(24), None);
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
fn a_chain_of_three_is_one_108_byte_write_with_part_0_last() {
    let mut chain = Tlc5947Chain::<_, 3>::new(SpiMock::<u8>::new(&[]));
    chain.set_channel(71, 0xABC).unwrap(); // part 2's OUT23: shifted first
    chain.set_channel(24, 0x123).unwrap(); // part 1's OUT0
    chain.set_channel(0, 0x0FF).unwrap(); // part 0's OUT0: shifted last
    let mut parts = [[0u16; 24]; 3];
    parts[2][23] = 0xABC;
    parts[1][0] = 0x123;
    parts[0][0] = 0x0FF;
    let frame = pack_chain(&parts);
    let bytes = frame.as_flattened();
    assert_eq!(bytes.len(), 108);
    assert_eq!(bytes[..3], [0xAB, 0xC0, 0x00]);
    assert_eq!(bytes[69..72], [0x00, 0x01, 0x23]);
    assert_eq!(bytes[105..], [0x00, 0x00, 0xFF]);
    // The farthest part's 36 bytes first, each part's in its own order.
    assert_eq!(frame[0], pack_frame(&parts[2]));
    assert_eq!(frame[1], pack_frame(&parts[1]));
    assert_eq!(frame[2], pack_frame(&parts[0]));
    assert_eq!(chain.channels().count(), 72);
    assert_eq!(chain.channel(71), Some(0xABC));
    assert_eq!(chain.channel(24), Some(0x123));
    assert_eq!(chain.channel(0), Some(0x0FF));
    assert_eq!(
        chain.set_channel(72, 1),
        Err(Error::OutOfRange { value: 72, max: 71 })
    );
    chain.release().done();

    let mut spi = SpiMock::new(&frame_tx(bytes.to_vec()));
    let mut chain = Tlc5947Chain::<_, 3>::new(spi.clone());
    chain.set_channel(71, 0xABC).unwrap();
    chain.set_channel(24, 0x123).unwrap();
    chain.set_channel(0, 0x0FF).unwrap();
    chain.flush().unwrap();
    spi.done();
}

/// Where a ring's RGB LED sits, in degrees clockwise from straight ahead (seen from above).
/// LightRing 1-0 (shared/reference/amiro-boards.md §6): triple 0 is NNW, then counter-clockwise in
/// 45° steps. LightRing 1-2 (docs/boards.md): LED 0 just right of the front, clockwise in 15° steps.
fn angle_10(triple: u8) -> f64 {
    (337.5 - 45.0 * f64::from(triple)).rem_euclid(360.0)
}
fn angle_12(triple: u8) -> f64 {
    7.5 + 15.0 * f64::from(triple)
}

#[test]
fn the_24_led_ring_gives_each_protocol_led_three_neighbours_where_the_8_led_ring_has_it() {
    let mut owner = [0u8; 24];
    for led in 1..=8u8 {
        let group = led_triples(3, led).unwrap();
        assert_eq!(group.len(), 3, "LED {led}");
        assert_eq!(group.start, 3 * (led - 1), "LED {led}");
        for t in group.clone() {
            assert_eq!(owner[usize::from(t)], 0, "triple {t} lit by two LEDs");
            owner[usize::from(t)] = led;
        }
        // Centred where the one-part ring has the same protocol LED.
        let centre = group.clone().map(angle_12).sum::<f64>() / 3.0;
        let one = led_triples(1, led).unwrap();
        assert_eq!(one.len(), 1);
        assert_eq!(centre, angle_10(one.start), "LED {led}");
    }
    assert!(owner.iter().all(|&led| led != 0), "every RGB LED is used");
    // LED 1 front-right (NNE), LED 8 front-left (NNW), as on 1-0.
    assert_eq!(angle_12(1), 22.5);
    assert_eq!(angle_12(22), 337.5);
    // The sources of the orientation (docs/boards.md): AMiRo-Apps' LightFloorData shows the
    // front-right floor sensor on LED 0 and the front-left on LED 23; its ObstacleAvoidance the NNE
    // ring sensor on LED 1 and the NNW one on LED 22 — each in the group of the protocol LED that
    // names that direction.
    assert!(led_triples(3, 1).unwrap().contains(&0));
    assert!(led_triples(3, 1).unwrap().contains(&1));
    assert!(led_triples(3, 8).unwrap().contains(&22));
    assert!(led_triples(3, 8).unwrap().contains(&23));
    assert_eq!(led_triples(3, 0), None);
    assert_eq!(led_triples(3, 9), None);
    assert_eq!(led_triples(2, 1), None, "no ring has two parts");
}

#[test]
fn a_24_led_ring_writes_a_protocol_leds_colour_to_its_nine_channels() {
    let mut parts = [[0u16; 24]; 3];
    // LED 3 = triples 6..=8 = chain channels 18..=26 (part 0's OUT18..23, part 1's OUT0..2).
    for triple in 6..9 {
        parts.as_flattened_mut()[3 * triple..3 * triple + 3]
            .copy_from_slice(&[GAMMA[200], GAMMA[100], GAMMA[50]]);
    }
    assert_eq!(parts[1][..3], [GAMMA[200], GAMMA[100], GAMMA[50]]);
    let mut spi = SpiMock::new(&frame_tx(pack_chain(&parts).as_flattened().to_vec()));
    let mut ring = LightRing24::new(spi.clone());
    ring.set_led(3, 200, 100, 50).unwrap();
    ring.flush().unwrap();
    assert_eq!(
        ring.set_led(9, 1, 1, 1),
        Err(Error::OutOfRange { value: 9, max: 8 })
    );
    assert_eq!(ring.driver().channels().filter(|&v| v != 0).count(), 9);
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
    fn the_packed_chain_holds_what_was_set_and_shifts_what_pack_chain_makes(
        values in proptest::collection::vec(0u16..=4095, 72),
        order in Just((0u8..72).collect::<Vec<u8>>()).prop_shuffle(),
    ) {
        let mut chain = Tlc5947Chain::<_, 3>::new(amiro_sensors::sim::SimLedChain::<3>::new());
        for &out in &order {
            chain.set_channel(out, values[usize::from(out)]).unwrap();
        }
        prop_assert_eq!(chain.channels().collect::<Vec<_>>(), values.clone());
        let mut parts = [[0u16; 24]; 3];
        parts.as_flattened_mut().copy_from_slice(&values);
        chain.flush().unwrap();
        let sim = chain.release();
        prop_assert_eq!(sim.outputs(), &values[..]);
        // The simulator decodes what pack_chain makes into the same values.
        let mut check = amiro_sensors::sim::SimLedChain::<3>::new();
        embedded_hal::spi::SpiDevice::write(&mut check, pack_chain(&parts).as_flattened()).unwrap();
        prop_assert_eq!(check.outputs(), &values[..]);
    }

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
