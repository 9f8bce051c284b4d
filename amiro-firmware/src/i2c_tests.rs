//! The engine and the bus against the register-level model (`i2c_model`): each AMiRo script shape
//! byte for byte on the wire, the register actions' order, every error path, and the queue's
//! order, ties, cancellation and timeouts with several clients.
use core::future::Future;
use core::pin::pin;
use core::task::{Context, Poll};

use amiro_sensors::drivers::{bno055, bq27500, hmc5883l, pca9544a, vcnl4020};
use amiro_sensors::script::{Failure, Readings, Script, ScriptError, Symbol};

use crate::i2c_bus::I2cBus;
use crate::i2c_engine::*;
use crate::i2c_model::{Access, Device, Model, Mux, Wire};
use crate::scripted_tests::{set_now, TestClock};
use crate::test_waker;

use Access::*;

/// The caller's wait for a condition the engine awaits (the bus's `settle`).
fn settle(engine: &mut Engine, model: &mut Model) {
    if engine.awaiting().is_some() {
        let cleared = (0..CONDITION_POLLS).any(|_| !engine.condition_pending(model));
        engine.resume(cleared, model);
    }
}

/// Runs `script` on a fresh engine; before serving each interrupt the bus runs on `late` more
/// steps (an interrupt served late). `None` if the bus stops with no interrupt and no end.
fn run(model: &mut Model, script: &Script, late: usize) -> Option<Result<Readings, ScriptError>> {
    let mut engine = Engine::new();
    let mut readings = Readings::for_script(script);
    let mut progress = engine.start(script, model);
    settle(&mut engine, model);
    for _ in 0..10_000 {
        if let Progress::Finished(result) = progress {
            assert!(engine.is_idle());
            // The bus finishes what it was asked (the last STOP).
            while model.advance() {}
            return Some(result.map(|()| readings));
        }
        let (ev, er) = model.pending();
        if ev || er {
            for _ in 0..late {
                model.advance();
            }
        }
        let (ev, er) = model.pending();
        progress = if er {
            let sr1 = model.read_sr1();
            engine.on_error(sr1, model)
        } else if ev {
            let sr1 = model.read_sr1();
            engine.on_event(sr1, script, &mut readings, model)
        } else if model.advance() {
            Progress::Running
        } else {
            return None;
        };
        settle(&mut engine, model);
    }
    panic!(
        "the script did not end: {:?}",
        &model.access[..model.access.len().min(40)]
    );
}

fn register_read(address: u8, register: u8, count: usize) -> Script {
    let mut script = Script::new();
    script.write_read(address, &[register], count).unwrap();
    script
}

fn expected_bytes(device: &Device, register: u8, count: usize) -> Vec<u8> {
    (0..count)
        .map(|n| device.registers[usize::from(register) + n])
        .collect()
}

/// The wire as the script says, with every address and written byte acknowledged and every read
/// byte but each operation's last acknowledged.
fn check_wire(model: &Model, script: &Script) {
    let expected: Vec<Symbol> = script.wire().collect();
    assert_eq!(model.symbols(), expected);
    assert!(model
        .wire
        .iter()
        .all(|w| !matches!(w, Wire::Sent(_, false))));
    assert!(model.violations.is_empty(), "{:?}", model.violations);
}

/// The accesses of a register read of `bytes.len()` ≥ 4 bytes from `address` (the HMC5883L's and
/// the BNO055's): the write phase, the repeated START, EV7 until three are left, method 2's ending.
fn register_read_accesses(address: u8, register: u8, bytes: &[u8]) -> Vec<Access> {
    let n = bytes.len();
    let mut a = vec![
        // The operation's START (after the STOP poll).
        StopPoll,
        Enable(Interrupts::Events),
        Cr1 {
            set: CR1_START,
            clear: 0,
        },
        // EV5: the address for writing.
        Sr1,
        WriteDr(address << 1),
        // EV6, then TXE.
        Sr1,
        Sr2,
        Enable(Interrupts::Buffer),
        // EV8_1: the register, the last byte: wait for BTF.
        Sr1,
        WriteDr(register),
        Enable(Interrupts::Events),
        // EV8_2 with a read to follow: the repeated START, and the wait for it to go out (BTF
        // stays set until it has).
        Sr1,
        Cr1 {
            set: CR1_START,
            clear: 0,
        },
        StartPoll,
        StartPoll,
        // EV5: the address for reading.
        Sr1,
        WriteDr((address << 1) | 1),
        // EV6 of N > 3: ACK on, POS off, before ADDR is cleared.
        Sr1,
        Cr1 {
            set: CR1_ACK,
            clear: CR1_POS,
        },
        Sr2,
        Enable(Interrupts::Buffer),
    ];
    for (k, &byte) in bytes[..n - 3].iter().enumerate() {
        a.extend([Sr1, ReadDr(byte)]);
        if k == n - 4 {
            a.push(Enable(Interrupts::Events));
        }
    }
    a.extend([
        // BTF with three left: ACK off, DataN-2, STOP, DataN-1.
        Sr1,
        Cr1 {
            set: 0,
            clear: CR1_ACK,
        },
        ReadDr(bytes[n - 3]),
        Cr1 {
            set: CR1_STOP,
            clear: 0,
        },
        ReadDr(bytes[n - 2]),
        Enable(Interrupts::Buffer),
        // EV7 of DataN; the script's end.
        Sr1,
        ReadDr(bytes[n - 1]),
        Enable(Interrupts::Off),
    ]);
    a
}

#[test]
fn an_hmc5883l_sample_is_method_2_byte_for_byte() {
    let device = Device::new(hmc5883l::ADDRESS);
    let mut model = Model::new(vec![device.clone()]);
    let script = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    let bytes = expected_bytes(&device, hmc5883l::reg::DATA_X_MSB, 6);
    assert_eq!(readings.of(0), bytes);
    check_wire(&model, &script);
    assert_eq!(
        model.access,
        register_read_accesses(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, &bytes)
    );
    // And the bus was left free: the STOP went out after the last byte.
    assert_eq!(model.wire.last(), Some(&Wire::Stop));
}

#[test]
fn a_bno055_nine_axis_burst_reads_eighteen_bytes() {
    let device = Device::new(bno055::ADDRESS);
    let mut model = Model::new(vec![device.clone()]);
    let script = register_read(bno055::ADDRESS, bno055::reg::ACC_DATA_X_LSB, 18);
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    let bytes = expected_bytes(&device, bno055::reg::ACC_DATA_X_LSB, 18);
    assert_eq!(readings.of(0), bytes);
    check_wire(&model, &script);
    assert_eq!(
        model.access,
        register_read_accesses(bno055::ADDRESS, bno055::reg::ACC_DATA_X_LSB, &bytes)
    );
}

#[test]
fn a_bq27500_command_is_the_two_byte_pos_ending() {
    let device = Device::new(bq27500::ADDRESS);
    let mut model = Model::new(vec![device.clone()]);
    let script = register_read(bq27500::ADDRESS, 0x08, 2);
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    let bytes = expected_bytes(&device, 0x08, 2);
    assert_eq!(readings.of(0), bytes);
    check_wire(&model, &script);
    // Data 1 acknowledged, data 2 not (POS).
    assert_eq!(
        model.wire[model.wire.len() - 3..],
        [
            Wire::Received(bytes[0], true),
            Wire::Received(bytes[1], false),
            Wire::Stop
        ]
    );
    let read_phase = model
        .access
        .iter()
        .rposition(|a| *a == WriteDr((bq27500::ADDRESS << 1) | 1))
        .unwrap();
    assert_eq!(
        model.access[read_phase + 1..],
        [
            // EV6: ACK low and POS high, then ADDR cleared; wait for BTF.
            Sr1,
            Cr1 {
                set: CR1_POS,
                clear: CR1_ACK
            },
            Sr2,
            Enable(Interrupts::Events),
            // BTF: STOP, then data 1 and data 2.
            Sr1,
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            ReadDr(bytes[0]),
            ReadDr(bytes[1]),
            Enable(Interrupts::Off),
        ]
    );
}

#[test]
fn a_one_byte_read_clears_addr_then_programs_stop_in_one_event() {
    let device = Device::new(bno055::ADDRESS);
    let mut model = Model::new(vec![device.clone()]);
    let script = register_read(bno055::ADDRESS, 0x3D, 1);
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    assert_eq!(readings.of(0), [device.registers[0x3D]]);
    check_wire(&model, &script);
    let read_phase = model
        .access
        .iter()
        .rposition(|a| *a == WriteDr((bno055::ADDRESS << 1) | 1))
        .unwrap();
    assert_eq!(
        model.access[read_phase + 1..],
        [
            // EV6: ACK off (and POS), ADDR cleared, STOP: one event, nothing between.
            Sr1,
            Cr1 {
                set: 0,
                clear: CR1_ACK | CR1_POS
            },
            Sr2,
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            Enable(Interrupts::Buffer),
            // EV7_1's byte.
            Sr1,
            ReadDr(device.registers[0x3D]),
            Enable(Interrupts::Off),
        ]
    );
}

/// The model catches the race the critical section prevents: a one-byte read whose STOP comes
/// after the byte (as if an interrupt came between clearing ADDR and setting STOP) clocks a byte
/// with no STOP programmed.
#[test]
fn the_one_byte_ending_interrupted_after_addr_is_caught_by_the_model() {
    struct Preempted<'a>(&'a mut Model);
    impl Block for Preempted<'_> {
        fn read_sr1(&mut self) -> u16 {
            self.0.read_sr1()
        }
        fn read_sr2(&mut self) -> u16 {
            let value = self.0.read_sr2();
            // The bus runs on before the next action.
            self.0.advance();
            value
        }
        fn read_dr(&mut self) -> u8 {
            self.0.read_dr()
        }
        fn write_dr(&mut self, byte: u8) {
            self.0.write_dr(byte)
        }
        fn modify_cr1(&mut self, set: u16, clear: u16) {
            self.0.modify_cr1(set, clear)
        }
        fn stop_pending(&mut self) -> bool {
            self.0.stop_pending()
        }
        fn start_pending(&mut self) -> bool {
            self.0.start_pending()
        }
        fn set_interrupts(&mut self, interrupts: Interrupts) {
            self.0.set_interrupts(interrupts)
        }
        fn clear_sr1(&mut self, flags: u16) {
            self.0.clear_sr1(flags)
        }
        fn reset(&mut self) {
            self.0.reset()
        }
    }
    let mut model = Model::new(vec![Device::new(0x28)]);
    let mut script = Script::new();
    script.read(0x28, 1).unwrap();
    let mut engine = Engine::new();
    let mut readings = Readings::for_script(&script);
    engine.start(&script, &mut Preempted(&mut model));
    settle(&mut engine, &mut model);
    for _ in 0..10 {
        let (ev, _) = model.pending();
        if ev {
            let sr1 = model.read_sr1();
            engine.on_event(sr1, &script, &mut readings, &mut Preempted(&mut model));
            settle(&mut engine, &mut model);
        } else if !model.advance() {
            break;
        }
    }
    assert!(
        model
            .violations
            .iter()
            .any(|v| v.starts_with("a byte not acknowledged with no STOP")),
        "{:?}",
        model.violations
    );
}

#[test]
fn a_three_byte_read_goes_straight_to_the_btf_ending() {
    let device = Device::new(0x28);
    let mut model = Model::new(vec![device.clone()]);
    let mut script = Script::new();
    script.read(0x28, 3).unwrap();
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    let bytes = expected_bytes(&device, 0, 3);
    assert_eq!(readings.of(0), bytes);
    check_wire(&model, &script);
    assert_eq!(
        model.access,
        [
            StopPoll,
            Enable(Interrupts::Events),
            Cr1 {
                set: CR1_START,
                clear: 0
            },
            Sr1,
            WriteDr(0x51),
            Sr1,
            Cr1 {
                set: CR1_ACK,
                clear: CR1_POS
            },
            Sr2,
            Enable(Interrupts::Events),
            Sr1,
            Cr1 {
                set: 0,
                clear: CR1_ACK
            },
            ReadDr(bytes[0]),
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            ReadDr(bytes[1]),
            Enable(Interrupts::Buffer),
            Sr1,
            ReadDr(bytes[2]),
            Enable(Interrupts::Off),
        ]
    );
}

#[test]
fn a_configuration_write_sends_every_byte_then_stop() {
    let mut model = Model::new(vec![Device::new(bno055::ADDRESS)]);
    let mut script = Script::new();
    script
        .write(bno055::ADDRESS, &[0x08, 0x11, 0x22, 0x33, 0x44])
        .unwrap();
    let readings = run(&mut model, &script, 0).unwrap().unwrap();
    assert!(readings.all().is_empty());
    check_wire(&model, &script);
    assert_eq!(
        model.devices[0].registers[0x08..0x0C],
        [0x11, 0x22, 0x33, 0x44]
    );
    // EV8_1 and EV8 write a byte each; the last turns TXE off; EV8_2 programs STOP; the end.
    let tail: Vec<Access> = model.access[model.access.len() - 6..].to_vec();
    assert_eq!(
        tail,
        [
            Sr1,
            WriteDr(0x44),
            Enable(Interrupts::Events),
            Sr1,
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            Enable(Interrupts::Off),
        ]
    );
}

/// DiWheelDrive's floor round: four VCNL4020 at one address behind the PCA9544A's four channels,
/// each selected (a transaction of its own: the mux connects at the STOP) then read twice.
fn floor() -> (Model, Script) {
    let model = floor_model();
    let mut script = Script::new();
    for channel in 0..4u8 {
        script
            .write(pca9544a::AMIRO_ADDRESS, &[pca9544a::ENABLE | channel])
            .unwrap();
        script
            .write_read(vcnl4020::ADDRESS, &[vcnl4020::reg::PROXIMITY_RESULT], 2)
            .unwrap();
        script
            .write_read(vcnl4020::ADDRESS, &[vcnl4020::reg::AMBIENT_RESULT], 2)
            .unwrap();
    }
    (model, script)
}

/// The floor's bus: the PCA9544A and four VCNL4020 at one address, one behind each channel.
fn floor_model() -> Model {
    let mut devices = Vec::new();
    for channel in 0..4u8 {
        let mut sensor = Device::new(vcnl4020::ADDRESS);
        sensor.channel = Some(channel);
        for r in sensor.registers.iter_mut() {
            *r = r.wrapping_add(channel * 16);
        }
        devices.push(sensor);
    }
    let mut model = Model::new(devices);
    model.mux = Some(Mux {
        address: pca9544a::AMIRO_ADDRESS,
        ..Mux::default()
    });
    model
}

#[test]
fn a_floor_round_reads_each_sensor_through_its_channel() {
    for late in 0..4 {
        let (mut model, script) = floor();
        let readings = run(&mut model, &script, late).unwrap().unwrap();
        for channel in 0..4usize {
            let sensor = &model.devices[channel];
            assert_eq!(readings.of(3 * channel), [] as [u8; 0]);
            assert_eq!(
                readings.of(3 * channel + 1),
                expected_bytes(sensor, 0x87, 2),
                "late {late}"
            );
            assert_eq!(
                readings.of(3 * channel + 2),
                expected_bytes(sensor, 0x85, 2)
            );
        }
        check_wire(&model, &script);
        // Every START after the first waited for the STOP before it to clear (the CR1 note; the
        // model also flags a CR1 write with a STOP pending).
        let starts: Vec<usize> = model
            .access
            .iter()
            .enumerate()
            .filter(|(k, a)| {
                **a == (Cr1 {
                    set: CR1_START,
                    clear: 0,
                }) && model.access[k - 2] == StopPoll
            })
            .map(|(k, _)| k)
            .collect();
        assert_eq!(starts.len(), 12);
        assert!(!model.access.contains(&Reset));
    }
}

#[test]
fn a_floor_select_is_a_write_whose_stop_clears_before_the_next_start() {
    let (mut model, script) = floor();
    run(&mut model, &script, 0).unwrap().unwrap();
    let select = model
        .access
        .iter()
        .position(|a| *a == WriteDr(pca9544a::ENABLE | 1))
        .unwrap();
    assert_eq!(
        model.access[select..select + 9],
        [
            WriteDr(pca9544a::ENABLE | 1),
            Enable(Interrupts::Events),
            // EV8_2: STOP; the next operation waits for it (two polls in the model) before its
            // START.
            Sr1,
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            StopPoll,
            StopPoll,
            Enable(Interrupts::Events),
            Cr1 {
                set: CR1_START,
                clear: 0
            },
            Sr1,
        ]
    );
    // The mux connected channel 1 at that STOP, before the sensor behind it was addressed.
    let stop = model
        .wire
        .iter()
        .position(|w| *w == Wire::Sent(pca9544a::ENABLE | 1, true))
        .unwrap();
    assert_eq!(model.wire[stop + 1..stop + 3], [Wire::Stop, Wire::Start]);
    assert_eq!(
        model.wire[stop + 3],
        Wire::Sent(vcnl4020::ADDRESS << 1, true)
    );
}

#[test]
fn a_bno055_verified_read_is_a_burst_then_a_one_byte_check() {
    let device = Device::new(bno055::ADDRESS);
    let mut script = Script::new();
    script
        .write_read(bno055::ADDRESS, &[bno055::reg::GYR_DATA_X_LSB], 6)
        .unwrap()
        .write_read(bno055::ADDRESS, &[bno055::reg::OPR_MODE], 1)
        .unwrap();
    for late in 0..3 {
        let mut model = Model::new(vec![device.clone()]);
        let readings = run(&mut model, &script, late).unwrap().unwrap();
        assert_eq!(
            readings.of(0),
            expected_bytes(&device, bno055::reg::GYR_DATA_X_LSB, 6)
        );
        assert_eq!(
            readings.of(1),
            expected_bytes(&device, bno055::reg::OPR_MODE, 1)
        );
        check_wire(&model, &script);
    }
}

#[test]
fn every_shape_is_the_same_when_the_interrupts_come_late() {
    let shapes: [(u8, usize); 6] = [(1, 1), (1, 2), (1, 3), (1, 4), (1, 6), (1, 18)];
    for (write, read) in shapes {
        let device = Device::new(0x28);
        let mut script = Script::new();
        let register = [0x10u8; 1];
        script
            .write_read(0x28, &register[..usize::from(write)], read)
            .unwrap();
        let mut wires = Vec::new();
        for late in 0..4 {
            let mut model = Model::new(vec![device.clone()]);
            let readings = run(&mut model, &script, late).unwrap().unwrap();
            assert_eq!(
                readings.of(0),
                expected_bytes(&device, 0x10, read),
                "read {read} late {late}"
            );
            check_wire(&model, &script);
            wires.push(model.wire.clone());
        }
        assert!(wires.windows(2).all(|w| w[0] == w[1]));
    }
}

#[test]
fn an_absent_device_is_a_nack_of_the_address_in_its_operation() {
    let (mut model, script) = floor();
    // The third sensor is gone: operation 7 (its proximity read) finds nobody.
    model.devices[2].nack_address = true;
    let result = run(&mut model, &script, 0).unwrap();
    assert_eq!(
        result.unwrap_err(),
        ScriptError {
            operation: 7,
            failure: Failure::NackAddress
        }
    );
    // The STOP the master owes after AF is on the wire right after the refused address, and the
    // block was not reset (a NACK leaves it usable).
    let refused = model
        .wire
        .iter()
        .position(|w| *w == Wire::Sent(vcnl4020::ADDRESS << 1, false))
        .unwrap();
    assert_eq!(model.wire[refused + 1..], [Wire::Stop]);
    let tail = &model.access[model.access.len() - 4..];
    assert_eq!(
        tail,
        [
            Sr1,
            ClearSr1(SR1_AF),
            Cr1 {
                set: CR1_STOP,
                clear: 0
            },
            Enable(Interrupts::Off)
        ]
    );
    assert!(!model.access.contains(&Reset));
    // The next script finds the bus usable.
    model.access.clear();
    let again = register_read(bno055::ADDRESS, 0, 1);
    model.devices.push(Device::new(bno055::ADDRESS));
    assert!(run(&mut model, &again, 0).unwrap().is_ok());
    assert!(model.violations.is_empty(), "{:?}", model.violations);
}

#[test]
fn a_refused_data_byte_is_a_nack_of_data() {
    let mut device = Device::new(bno055::ADDRESS);
    device.nack_data = Some(2);
    let mut model = Model::new(vec![device]);
    let mut script = Script::new();
    script.read(bno055::ADDRESS, 2).unwrap();
    script.write(bno055::ADDRESS, &[0x08, 1, 2, 3]).unwrap();
    let result = run(&mut model, &script, 1).unwrap();
    assert_eq!(
        result.unwrap_err(),
        ScriptError {
            operation: 1,
            failure: Failure::NackData
        }
    );
    assert_eq!(
        model.wire[model.wire.len() - 2..],
        [Wire::Sent(2, false), Wire::Stop]
    );
    assert!(model.violations.is_empty(), "{:?}", model.violations);
}

#[test]
fn arbitration_loss_bus_error_and_overrun_reset_the_block() {
    // (fault, wire byte, failure): ARLO on the written register, BERR on a read byte.
    for (arlo, at, failure) in [
        (true, 1, Failure::ArbitrationLoss),
        (false, 4, Failure::Bus),
    ] {
        let mut model = Model::new(vec![Device::new(0x1E)]);
        if arlo {
            model.arbitration_loss_at = Some(at);
        } else {
            model.bus_error_at = Some(at);
        }
        let script = register_read(0x1E, 3, 6);
        let result = run(&mut model, &script, 0).unwrap();
        assert_eq!(
            result.unwrap_err(),
            ScriptError {
                operation: 0,
                failure
            }
        );
        let flag = if arlo { SR1_ARLO } else { SR1_BERR };
        assert_eq!(
            model.access[model.access.len() - 3..],
            [Sr1, ClearSr1(flag), Reset]
        );
    }
    // OVR (master mode has none but a faulty block's): raised in the middle of a read.
    let mut model = Model::new(vec![Device::new(0x1E)]);
    let script = register_read(0x1E, 3, 6);
    let mut engine = Engine::new();
    let mut readings = Readings::for_script(&script);
    engine.start(&script, &mut model);
    settle(&mut engine, &mut model);
    let mut served = 0;
    let result = loop {
        let (ev, _) = model.pending();
        if ev {
            served += 1;
            if served == 6 {
                model.sr1 |= SR1_OVR;
            }
        }
        let (ev, er) = model.pending();
        let progress = if er {
            let sr1 = model.read_sr1();
            engine.on_error(sr1, &mut model)
        } else if ev {
            let sr1 = model.read_sr1();
            engine.on_event(sr1, &script, &mut readings, &mut model)
        } else {
            assert!(model.advance());
            Progress::Running
        };
        settle(&mut engine, &mut model);
        if let Progress::Finished(result) = progress {
            break result;
        }
    };
    assert_eq!(
        result.unwrap_err(),
        ScriptError {
            operation: 0,
            failure: Failure::Overrun
        }
    );
    assert_eq!(model.access.last(), Some(&Reset));
    assert!(engine.is_idle());
}

#[test]
fn an_event_the_sequence_has_no_step_for_resets_the_block() {
    let mut model = Model::new(vec![Device::new(0x1E)]);
    let script = register_read(0x1E, 3, 6);
    let mut engine = Engine::new();
    let mut readings = Readings::for_script(&script);
    engine.start(&script, &mut model);
    settle(&mut engine, &mut model);
    // SB while the engine waits for ADDR.
    model.advance();
    let sr1 = model.read_sr1();
    engine.on_event(sr1, &script, &mut readings, &mut model);
    let progress = engine.on_event(SR1_SB, &script, &mut readings, &mut model);
    assert_eq!(
        progress,
        Progress::Finished(Err(ScriptError {
            operation: 0,
            failure: Failure::UnexpectedEvent
        }))
    );
    assert_eq!(model.access.last(), Some(&Reset));
    // A stray event with nothing running turns the interrupts off; so does a stray error.
    assert_eq!(
        engine.on_event(SR1_TXE, &script, &mut readings, &mut model),
        Progress::Running
    );
    assert_eq!(model.access.last(), Some(&Enable(Interrupts::Off)));
    assert_eq!(engine.on_error(SR1_AF, &mut model), Progress::Running);
    assert_eq!(
        model.access[model.access.len() - 2..],
        [ClearSr1(SR1_AF), Enable(Interrupts::Off)]
    );
}

#[test]
fn an_operation_is_taken_from_the_script_at_its_sb_and_a_script_without_it_is_left_stray() {
    // The engine reads an operation's address and counts at its SB, not at the end of the
    // operation before: a two-operation script addresses each device with its own direction.
    let mut model = Model::new(vec![Device::new(0x13), Device::new(0x77)]);
    let mut script = Script::new();
    script.write(0x77, &[0x05]).unwrap();
    script.write_read(0x13, &[0x87], 2).unwrap();
    let result = run(&mut model, &script, 0).unwrap();
    assert_eq!(result.unwrap().of(1).len(), 2);
    check_wire(&model, &script);

    // An SB with a script that lacks the running operation (the bus never passes one): nothing
    // to address; the interrupts off, no reset, the script left to its client's timeout.
    let mut model = Model::new(vec![Device::new(0x1E)]);
    let script = register_read(0x1E, 3, 6);
    let mut engine = Engine::new();
    engine.start(&script, &mut model);
    settle(&mut engine, &mut model);
    model.advance();
    let sr1 = model.read_sr1();
    assert_ne!(sr1 & SR1_SB, 0);
    let empty = Script::new();
    let mut readings = Readings::for_script(&empty);
    let accesses = model.access.len();
    assert_eq!(
        engine.on_event(sr1, &empty, &mut readings, &mut model),
        Progress::Running
    );
    assert_eq!(model.access[accesses..], [Enable(Interrupts::Off)]);
    assert!(engine.is_idle());
}

#[test]
fn a_stretch_holds_the_script_and_a_stuck_bus_is_aborted_and_reset() {
    let device = Device::new(0x1E);
    let script = register_read(0x1E, 3, 6);
    // Stretched before the fourth wire byte: no event comes until the device lets go.
    let mut model = Model::new(vec![device.clone()]);
    model.hold_at = Some(4);
    assert_eq!(run(&mut model, &script, 0), None);
    let events_while_held = model.access.len();
    assert!(!model.advance() && model.pending() == (false, false));
    assert_eq!(model.access.len(), events_while_held);
    // (`run` starts over: the same script on a bus that stretches once, then lets go.)
    let mut model = Model::new(vec![device.clone()]);
    model.hold_at = Some(4);
    let mut engine = Engine::new();
    let mut readings = Readings::for_script(&script);
    engine.start(&script, &mut model);
    settle(&mut engine, &mut model);
    let mut released = false;
    let result = loop {
        let (ev, er) = model.pending();
        let progress = if er {
            let sr1 = model.read_sr1();
            engine.on_error(sr1, &mut model)
        } else if ev {
            let sr1 = model.read_sr1();
            engine.on_event(sr1, &script, &mut readings, &mut model)
        } else if model.advance() {
            Progress::Running
        } else {
            assert!(!released, "held twice");
            released = true;
            model.release();
            Progress::Running
        };
        settle(&mut engine, &mut model);
        if let Progress::Finished(result) = progress {
            break result;
        }
    };
    assert!(released);
    while model.advance() {}
    result.unwrap();
    assert_eq!(readings.of(0), expected_bytes(&device, 3, 6));
    check_wire(&model, &script);
    // A bus held low for ever: no START is granted; the client's timeout aborts.
    let mut model = Model::new(vec![device]);
    model.stuck = true;
    let mut engine = Engine::new();
    engine.start(&script, &mut model);
    settle(&mut engine, &mut model);
    assert!(!model.advance() && model.pending() == (false, false));
    assert!(!engine.is_idle());
    engine.abort(&mut model);
    assert!(engine.is_idle());
    assert_eq!(model.access.last(), Some(&Reset));
    assert!(model.wire.is_empty());
}

#[test]
fn a_stop_that_never_clears_resets_the_block_before_the_next_start() {
    let mut model = Model::new(vec![Device::new(0x1E)]);
    let mut script = Script::new();
    script.write(0x1E, &[1]).unwrap().read(0x1E, 1).unwrap();
    model.stop_polls = CONDITION_POLLS + 1;
    assert!(run(&mut model, &script, 0).unwrap().is_ok());
    let polls = model.access.iter().filter(|a| **a == StopPoll).count();
    // The first START's one poll; the second's CONDITION_POLLS, then the reset.
    assert_eq!(polls, 1 + CONDITION_POLLS as usize);
    let reset = model.access.iter().position(|a| *a == Reset).unwrap();
    assert_eq!(
        model.access[reset + 1..reset + 3],
        [
            Enable(Interrupts::Events),
            Cr1 {
                set: CR1_START,
                clear: 0
            }
        ]
    );
}

// The queue.

fn pump<const N: usize>(bus: &I2cBus<Model, N>) {
    for _ in 0..10_000 {
        let (ev, er) = bus.with_block(|m| m.pending());
        if er {
            bus.on_error();
        } else if ev {
            bus.on_event();
        } else if !bus.with_block(|m| m.advance()) {
            return;
        }
    }
    panic!("the bus did not settle");
}

/// The addresses of the scripts' first operations as they went on the wire, in order.
fn started_addresses(model: &Model) -> Vec<u8> {
    let mut out = Vec::new();
    let mut after_start = false;
    for w in &model.wire {
        if let (true, Wire::Sent(byte, _)) = (after_start, w) {
            if out.last() != Some(&(byte >> 1)) {
                out.push(byte >> 1);
            }
        }
        after_start = matches!(w, Wire::Start);
    }
    out
}

fn devices(addresses: &[u8]) -> Model {
    Model::new(addresses.iter().map(|&a| Device::new(a)).collect())
}

#[test]
fn the_most_urgent_waiting_script_runs_next_and_each_client_is_woken_once() {
    let bus = I2cBus::new(devices(&[0x10, 0x11, 0x12, 0x13]), [1, 3, 2, 5]);
    let clients: Vec<_> = (0..4).map(|c| bus.client(c).unwrap()).collect();
    assert!(bus.client(4).is_none());
    let scripts: Vec<Script> = (0..4)
        .map(|c| register_read(0x10 + c as u8, 0, 2))
        .collect();
    let wakers: Vec<_> = (0..4).map(|_| test_waker::counting()).collect();
    let mut f0 = pin!(bus.run(clients[0], scripts[0]));
    let mut f1 = pin!(bus.run(clients[1], scripts[1]));
    let mut f2 = pin!(bus.run(clients[2], scripts[2]));
    let mut f3 = pin!(bus.run(clients[3], scripts[3]));
    let cx = |k: usize| Context::from_waker(&wakers[k].1);
    // Client 0 (priority 1) finds the bus idle and starts; 2, 1 then 3 wait.
    assert!(f0.as_mut().poll(&mut cx(0)).is_pending());
    assert!(f2.as_mut().poll(&mut cx(2)).is_pending());
    assert!(f1.as_mut().poll(&mut cx(1)).is_pending());
    assert!(f3.as_mut().poll(&mut cx(3)).is_pending());
    pump(&bus);
    // Non-preemptive: 0 finishes, then 3 (priority 5), 1 (3), 2 (2).
    assert_eq!(
        bus.with_block(|m| started_addresses(m)),
        [0x10, 0x13, 0x11, 0x12]
    );
    for (k, f) in [f0.as_mut(), f1.as_mut(), f2.as_mut(), f3.as_mut()]
        .into_iter()
        .enumerate()
    {
        assert_eq!(wakers[k].0.count(), 1, "client {k}");
        let Poll::Ready(Ok(readings)) = f.poll(&mut cx(k)) else {
            panic!("client {k} not done");
        };
        let address = 0x10 + k as u8;
        assert_eq!(readings.of(0), [address, 1 ^ address]);
    }
    assert!(bus.with_block(|m| m.violations.is_empty()));
}

#[test]
fn equal_priorities_run_in_submission_order() {
    let bus = I2cBus::new(devices(&[0x10, 0x11, 0x12, 0x13]), [9, 4, 4, 4]);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let c = |k| bus.client(k).unwrap();
    let mut running = pin!(bus.run(c(0), register_read(0x10, 0, 1)));
    let mut third = pin!(bus.run(c(1), register_read(0x11, 0, 1)));
    let mut first = pin!(bus.run(c(3), register_read(0x13, 0, 1)));
    let mut second = pin!(bus.run(c(2), register_read(0x12, 0, 1)));
    assert!(running.as_mut().poll(&mut cx).is_pending());
    assert!(first.as_mut().poll(&mut cx).is_pending());
    assert!(second.as_mut().poll(&mut cx).is_pending());
    assert!(third.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    assert_eq!(
        bus.with_block(|m| started_addresses(m)),
        [0x10, 0x13, 0x12, 0x11]
    );
    for f in [running, first, second, third] {
        assert!(matches!(f.poll(&mut cx), Poll::Ready(Ok(_))));
    }
}

#[test]
fn a_dropped_waiting_transfer_is_removed_and_a_dropped_running_one_aborted() {
    let bus = I2cBus::new(devices(&[0x10, 0x11, 0x12]), [1, 2, 3]);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let c = |k| bus.client(k).unwrap();
    let mut running = Box::pin(bus.run(c(0), register_read(0x10, 0, 6)));
    let mut waiting = Box::pin(bus.run(c(2), register_read(0x12, 0, 2)));
    let mut last = pin!(bus.run(c(1), register_read(0x11, 0, 2)));
    assert!(running.as_mut().poll(&mut cx).is_pending());
    assert!(waiting.as_mut().poll(&mut cx).is_pending());
    assert!(last.as_mut().poll(&mut cx).is_pending());
    // The most urgent waiting one gives up: it is never run.
    drop(waiting);
    // The running one is dropped halfway (after its first bytes): aborted, the block reset, and
    // client 1's script starts at once.
    for _ in 0..12 {
        let (ev, _) = bus.with_block(|m| m.pending());
        if ev {
            bus.on_event();
        } else {
            bus.with_block(|m| m.advance());
        }
    }
    bus.with_block(|m| m.access.clear());
    drop(running);
    let after_drop = bus.with_block(|m| m.access.clone());
    assert_eq!(
        after_drop[..4],
        [
            Reset,
            StopPoll,
            Enable(Interrupts::Events),
            Cr1 {
                set: CR1_START,
                clear: 0
            }
        ]
    );
    pump(&bus);
    assert_eq!(bus.with_block(|m| started_addresses(m)), [0x10, 0x11]);
    let Poll::Ready(Ok(readings)) = last.as_mut().poll(&mut cx) else {
        panic!("client 1 not done");
    };
    assert_eq!(readings.of(0), [0x11, 0x10]);
    // The bus is free again for client 2.
    let mut again = pin!(bus.run(c(2), register_read(0x12, 0, 1)));
    assert!(again.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    assert!(matches!(again.poll(&mut cx), Poll::Ready(Ok(_))));
}

#[test]
fn a_timeout_on_a_stuck_device_aborts_its_own_script_only() {
    // Client 0's device stretches SCL for ever in the middle of its script; clients 1 and 2 wait.
    // Client 0's timeout drops its transfer; the bus then serves 2 and 1 in priority order.
    let bus = I2cBus::new(devices(&[0x10, 0x11, 0x12]), [2, 1, 3]);
    let wakers: Vec<_> = (0..3).map(|_| test_waker::counting()).collect();
    let cx = |k: usize| Context::from_waker(&wakers[k].1);
    let c = |k| bus.client(k).unwrap();
    bus.with_block(|m| m.hold_at = Some(3));
    let mut stuck = Box::pin(bus.run(c(0), register_read(0x10, 0, 4)));
    let mut one = pin!(bus.run(c(1), register_read(0x11, 0, 2)));
    let mut two = pin!(bus.run(c(2), register_read(0x12, 0, 2)));
    assert!(stuck.as_mut().poll(&mut cx(0)).is_pending());
    assert!(one.as_mut().poll(&mut cx(1)).is_pending());
    assert!(two.as_mut().poll(&mut cx(2)).is_pending());
    pump(&bus);
    // Nothing more happens while the device holds the clock; nobody is woken.
    assert!(wakers.iter().all(|(w, _)| w.count() == 0));
    assert!(stuck.as_mut().poll(&mut cx(0)).is_pending());
    // The timeout: the transfer dropped. The device lets go when the block resets its lines.
    drop(stuck);
    bus.with_block(|m| m.release());
    pump(&bus);
    assert_eq!(wakers[0].0.count(), 0);
    assert_eq!(wakers[2].0.count(), 1);
    assert_eq!(wakers[1].0.count(), 1);
    assert_eq!(bus.with_block(|m| started_addresses(m)), [0x10, 0x12, 0x11]);
    assert!(matches!(two.poll(&mut cx(2)), Poll::Ready(Ok(_))));
    assert!(matches!(one.poll(&mut cx(1)), Poll::Ready(Ok(_))));
}

#[test]
fn a_client_has_one_script_at_a_time_and_a_failure_reaches_only_its_own() {
    let mut model = devices(&[0x10]);
    model.devices.push({
        let mut absent = Device::new(0x11);
        absent.nack_address = true;
        absent
    });
    let bus = I2cBus::new(model, [1, 1]);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let c = |k| bus.client(k).unwrap();
    let mut first = pin!(bus.run(c(0), register_read(0x10, 0, 2)));
    let mut second = pin!(bus.run(c(0), register_read(0x10, 0, 2)));
    let mut other = pin!(bus.run(c(1), register_read(0x11, 0, 2)));
    assert!(first.as_mut().poll(&mut cx).is_pending());
    assert_eq!(
        second.as_mut().poll(&mut cx),
        Poll::Ready(Err(ScriptError {
            operation: 0,
            failure: Failure::Busy
        }))
    );
    assert!(other.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    assert!(matches!(first.as_mut().poll(&mut cx), Poll::Ready(Ok(_))));
    assert_eq!(
        other.poll(&mut cx),
        Poll::Ready(Err(ScriptError {
            operation: 0,
            failure: Failure::NackAddress
        }))
    );
    // A transfer polled again after it resolved does not run its script again.
    let wire = bus.with_block(|m| m.wire.len());
    assert_eq!(
        first.poll(&mut cx),
        Poll::Ready(Err(ScriptError {
            operation: 0,
            failure: Failure::Busy
        }))
    );
    pump(&bus);
    assert_eq!(bus.with_block(|m| m.wire.len()), wire);
    // An empty script needs no bus.
    let mut empty = pin!(bus.run(c(0), Script::new()));
    assert!(matches!(empty.as_mut().poll(&mut cx), Poll::Ready(Ok(r)) if r.all().is_empty()));
}

/// The condition wait ends on the cycle counter, not at the poll cap, where the counter runs: a
/// STOP held past two SCL periods (a device holding SCL) is given up after the counter passes
/// `condition_cycles`, and the next START set on a reset block, as at the cap.
#[test]
fn a_held_stop_ends_the_condition_wait_on_the_cycle_counter() {
    let held = |cycles_per_poll: u32| {
        let bus = I2cBus::new(devices(&[0x1E]), [1]);
        bus.with_block(|m| {
            m.stop_polls = CONDITION_POLLS + 1;
            m.cycles_per_poll = cycles_per_poll;
            // 5.6 µs at 72 MHz.
            m.condition_cycles = 403;
        });
        let mut script = Script::new();
        script.write(0x1E, &[1]).unwrap().read(0x1E, 1).unwrap();
        let client = bus.client(0).unwrap();
        let mut transfer = pin!(bus.run(client, script));
        let (_, waker) = test_waker::counting();
        let mut cx = Context::from_waker(&waker);
        assert!(transfer.as_mut().poll(&mut cx).is_pending());
        pump(&bus);
        let done = transfer.as_mut().poll(&mut cx);
        assert!(matches!(done, Poll::Ready(Ok(_))), "{done:?}");
        bus.with_block(|m| {
            assert!(m.violations.is_empty(), "{:?}", m.violations);
            let polls = m.access.iter().filter(|a| **a == StopPoll).count();
            let resets = m.access.iter().filter(|a| **a == Reset).count();
            (polls, resets)
        })
    };
    // No counter (QEMU): the first START's one poll, the second's CONDITION_POLLS.
    assert_eq!(held(0), (1 + CONDITION_POLLS as usize, 1));
    // 10 cycles a poll: the wait ends at the first poll past 403 cycles, the 41st.
    assert_eq!(held(10), (1 + 41, 1));
}

/// Serves `bus` as the chip would until nothing moves: its interrupts while raised, else the
/// bus's own next move. Returns the handler entries (I2Cx_EV and I2Cx_ER).
fn pump_counting<const N: usize>(bus: &I2cBus<Model, N>) -> usize {
    let mut entries = 0;
    for _ in 0..10_000 {
        let (ev, er) = bus.with_block(|m| m.pending());
        if er {
            bus.on_error();
        } else if ev {
            bus.on_event();
        } else if !bus.with_block(|m| m.advance()) {
            return entries;
        }
        entries += usize::from(ev || er);
    }
    panic!("the handler re-entered without end: {entries} entries");
}

/// What a stretched repeated START cost: the handler's entries, the re-arm task's looks, and the
/// client's transfer (`None`: still pending when nothing more moves).
struct Stretch {
    entries: usize,
    looks: usize,
    result: Option<Result<Readings, ScriptError>>,
}

/// An HMC5883L sample (write the register, repeated START, read six) whose device holds SCL after
/// the register byte's acknowledge (before wire byte 2: the repeated START) for `hold_us`
/// (`None`: for ever). The time is the re-arm task's: each look comes `STRETCH_REARM_US` after
/// the stall (or the last look), and the device lets go at the first look at or after `hold_us`.
fn stretched_repeated_start(hold_us: Option<u32>) -> (Stretch, I2cBus<Model, 1>) {
    let device = Device::new(hmc5883l::ADDRESS);
    let bus = I2cBus::new(Model::new(vec![device]), [1]);
    bus.with_block(|m| m.hold_at = Some(2));
    let client = bus.client(0).unwrap();
    let script = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
    let (client_woken, client_waker) = test_waker::counting();
    let (rearm_woken, rearm_waker) = test_waker::counting();
    let mut transfer = Box::pin(bus.run(client, script));
    assert!(transfer
        .as_mut()
        .poll(&mut Context::from_waker(&client_waker))
        .is_pending());
    let mut entries = 0;
    let mut looks = 0;
    let mut now_us = 0;
    let result = loop {
        entries += pump_counting(&bus);
        if client_woken.count() > 0 {
            let Poll::Ready(result) = transfer
                .as_mut()
                .poll(&mut Context::from_waker(&client_waker))
            else {
                panic!("woken and pending");
            };
            break Some(result);
        }
        // The re-arm task's `stalled().await`.
        let mut stalled = pin!(bus.stalled());
        let Poll::Ready(stall) = stalled
            .as_mut()
            .poll(&mut Context::from_waker(&rearm_waker))
        else {
            break None;
        };
        // Its delay, then its look.
        now_us += STRETCH_REARM_US;
        if hold_us.is_some_and(|hold| now_us >= hold) {
            // The device lets go; the START goes out within an SCL period, before the look.
            bus.with_block(|m| {
                m.release();
                m.advance()
            });
        }
        bus.rearm(stall);
        looks += 1;
    };
    // The re-arm task was woken by the stall (its waker registered before), never otherwise.
    assert!(rearm_woken.count() <= 1);
    // Pending: the client's timeout drops the transfer, which aborts the script (resolved: no
    // effect).
    drop(transfer);
    (
        Stretch {
            entries,
            looks,
            result,
        },
        bus,
    )
}

/// A device that stretches SCL for 4 ms at a repeated START (the bq27500's stated worst case
/// within a packet): the handler is entered no more often than on an unstretched bus, the re-arm
/// task looks once per `STRETCH_REARM_US` of the stretch, and the script ends with its readings.
#[test]
fn a_four_millisecond_stretch_at_a_repeated_start_costs_one_look_per_interval() {
    let (plain, _) = stretched_repeated_start(Some(0));
    let (stretch, bus) = stretched_repeated_start(Some(4_000));
    // SB, ADDR, TXE, BTF; SB, ADDR, RXNE × 3, BTF, RXNE.
    assert_eq!(plain.entries, 11);
    assert_eq!(stretch.entries, 11);
    // The first look finds the START still held (the device lets go at 4 ms: the 16th look).
    assert_eq!(plain.looks, 1);
    assert_eq!(stretch.looks, 4_000 / STRETCH_REARM_US as usize);
    let device = Device::new(hmc5883l::ADDRESS);
    let bytes = expected_bytes(&device, hmc5883l::reg::DATA_X_MSB, 6);
    assert_eq!(stretch.result.unwrap().unwrap().of(0), bytes);
    bus.with_block(|m| {
        let script = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
        check_wire(m, &script);
        // One condition wait (CONDITION_POLLS polls, the counter not running) at the BTF, then
        // one poll per look.
        let start_polls = m.access.iter().filter(|a| **a == StartPoll).count();
        assert_eq!(start_polls, CONDITION_POLLS as usize + 16);
        // The stall masked the event interrupt (errors kept) and the last look unmasked it.
        let masked = m
            .access
            .iter()
            .position(|a| *a == Enable(Interrupts::Errors))
            .unwrap();
        let unmasked = m.access.iter().rposition(|a| *a == StartPoll).unwrap();
        assert!(masked < unmasked);
        assert_eq!(m.access[unmasked + 1], Enable(Interrupts::Events));
    });
}

/// A device that holds SCL for ever at a repeated START: BTF stays raised, yet the handler is not
/// entered again (the event interrupt masked), the re-arm task looks `MAX_REARMS` times and then
/// stops, and the client's timeout aborts the script (the block reset).
#[test]
fn a_device_holding_scl_for_ever_at_a_repeated_start_stops_after_max_rearms() {
    let (stretch, bus) = stretched_repeated_start(None);
    // SB, ADDR, TXE, BTF: the write phase, then nothing.
    assert_eq!(stretch.entries, 4);
    assert_eq!(stretch.looks, usize::from(MAX_REARMS));
    assert!(stretch.result.is_none());
    bus.with_block(|m| {
        let start_polls = m.access.iter().filter(|a| **a == StartPoll).count();
        assert_eq!(
            start_polls,
            CONDITION_POLLS as usize + usize::from(MAX_REARMS)
        );
        // The timeout's abort reset the block (after the last look, nothing else).
        assert_eq!(m.access.last(), Some(&Reset));
        assert!(m.violations.is_empty(), "{:?}", m.violations);
    });
    // Before the abort, BTF was raised with the event interrupt masked: on the old engine every
    // instant of it was a handler entry. Shown on a fresh bus stalled the same way.
    let bus = I2cBus::new(Model::new(vec![Device::new(hmc5883l::ADDRESS)]), [1]);
    bus.with_block(|m| m.hold_at = Some(2));
    let script = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
    let (_, waker) = test_waker::counting();
    let mut transfer = pin!(bus.run(bus.client(0).unwrap(), script));
    assert!(transfer
        .as_mut()
        .poll(&mut Context::from_waker(&waker))
        .is_pending());
    assert_eq!(pump_counting(&bus), 4);
    bus.with_block(|m| {
        assert_ne!(m.sr1 & SR1_BTF, 0);
        assert_eq!(m.cr2 & CR2_ITEVTEN, 0);
        assert_ne!(m.cr2 & CR2_ITERREN, 0);
        assert_eq!(m.pending(), (false, false));
    });
    // An error while stalled still ends the script (the error interrupt kept).
    bus.with_block(|m| m.sr1 |= SR1_BERR);
    assert_eq!(pump_counting(&bus), 1);
    assert_eq!(
        transfer.poll(&mut Context::from_waker(&waker)),
        Poll::Ready(Err(ScriptError {
            operation: 0,
            failure: Failure::Bus
        }))
    );
    let mut stalled = pin!(bus.stalled());
    assert!(stalled
        .as_mut()
        .poll(&mut Context::from_waker(&waker))
        .is_pending());
}

/// The engine's interrupts per sample script of DiWheelDrive 1-1's groups, counted on the register
/// model with the scripts the groups build (the events a timing file states for them,
/// `tests/scripted_i2c_analysis.rs`): the HMC5883L's sample 11 (SB, ADDR, TXE, BTF; SB, ADDR,
/// RXNE × 3, BTF, RXNE), the floor's round 44 (per sensor the select's SB, ADDR, TXE, BTF and the
/// proximity read's SB, ADDR, TXE, BTF, SB, ADDR, BTF).
#[test]
fn dwd_sample_scripts_raise_the_stated_events() {
    use amiro_can::Topic;
    use amiro_sensors::drivers::floor::FloorSensors;
    use amiro_sensors::drivers::scripted::{Job, Next, ScriptedSensors, Scripts};
    use amiro_sensors::drivers::suite::{Compass, Supervised};
    use amiro_sensors::sim::{NoDelay, SimCompassBus, SimFloorBus};

    fn first_script<G: ScriptedSensors>(group: &mut Supervised<G>, topic: Topic) -> Script {
        let mut job = Job::new();
        match group.begin_scripted(&mut job, topic, 1_000) {
            Next::Run { script, .. } => script,
            Next::Done(_) => panic!("no script for {topic:?}"),
        }
    }

    let mut compass = Supervised::boot(
        Compass::<Scripts>::scripted(),
        &mut SimCompassBus::new(),
        &mut NoDelay,
    );
    let script = first_script(&mut compass, Topic::MagnetometerX);
    let model = Model::new(vec![Device::new(hmc5883l::ADDRESS)]);
    assert_eq!(entries(model, script), 11);

    let mut floor = Supervised::boot(
        FloorSensors::<Scripts>::scripted(),
        &mut SimFloorBus::new(),
        &mut NoDelay,
    );
    let script = first_script(&mut floor, Topic::FloorProximity);
    assert_eq!(entries(floor_model(), script), 44);
}

/// Runs `script` alone on a bus over `model` and returns the event handler's entries; the client is
/// woken once, its script succeeds and the wire is the script's.
fn entries(model: Model, script: Script) -> usize {
    let bus = I2cBus::new(model, [1]);
    let (woken, waker) = test_waker::counting();
    let mut transfer = pin!(bus.run(bus.client(0).unwrap(), script));
    assert!(transfer
        .as_mut()
        .poll(&mut Context::from_waker(&waker))
        .is_pending());
    let entries = pump_counting(&bus);
    assert_eq!(woken.count(), 1);
    assert!(matches!(
        transfer.poll(&mut Context::from_waker(&waker)),
        Poll::Ready(Ok(_))
    ));
    bus.with_block(|m| {
        check_wire(m, &script);
    });
    entries
}

/// `events` counts the interrupts the engine serves for each shape the AMiRo scripts have: the
/// handler entries on the register model, every byte acknowledged.
#[test]
fn events_are_the_handler_entries_of_each_script_shape() {
    let device = || devices(&[0x1E]);
    for count in [1, 2, 3, 4, 6, 18] {
        let script = register_read(0x1E, 0, count);
        assert_eq!(
            events(&script) as usize,
            entries(device(), script),
            "{count}"
        );
        let mut read = Script::new();
        read.read(0x1E, count).unwrap();
        assert_eq!(events(&read) as usize, entries(device(), read), "{count}");
    }
    for bytes in [&[1u8][..], &[1, 2], &[1, 2, 3, 4]] {
        let mut write = Script::new();
        write.write(0x1E, bytes).unwrap();
        assert_eq!(events(&write) as usize, entries(device(), write));
    }
    // A ring round (four selects and proximity reads): 44, as the analysis states it.
    let mut round = Script::new();
    for channel in 0..4u8 {
        round
            .write(pca9544a::AMIRO_ADDRESS, &[0x04 | channel])
            .unwrap()
            .write_read(vcnl4020::ADDRESS, &[0x87], 2)
            .unwrap();
    }
    assert_eq!(events(&round), 44);
    assert_eq!(entries(floor_model(), round), 44);
    // A gauge's standard command: 7; its deadline 120 µs on the wire + 7 × 200 µs.
    let gauge = register_read(bq27500::ADDRESS, 0x08, 2);
    assert_eq!(events(&gauge), 7);
    assert_eq!(deadline_us(&gauge), 120 + 7 * FLAG_ALLOWANCE_US);
}

/// What a run under the watch gave: the first client's result, the second's, the watch's looks at
/// the stall (CR1.START polls after the condition wait), the bus clears, and when the first
/// client's result came (µs).
struct Watched {
    first: Result<Readings, ScriptError>,
    second: Result<Readings, ScriptError>,
    clears: usize,
    ended_at_us: u64,
    model: Model,
}

/// Two clients on one bus under its watch (`I2cBus::serve_watch` on the scripted tests' clock): client 0
/// (the more urgent) reads the HMC5883L's six data bytes from a device that holds SCL from wire
/// byte `hold_at` on for `hold_us` (`None`: for ever), client 1 waits behind it with a gauge
/// read. The time moves in 10 µs steps; the device lets go at `hold_us`; the bus clear the watch
/// calls releases a device still holding SCL (as the nine pulses and the STOP free it).
fn under_watch(hold_at: usize, hold_us: Option<u64>) -> Watched {
    set_now(0);
    let mut model = Model::new(vec![
        Device::new(hmc5883l::ADDRESS),
        Device::new(bq27500::ADDRESS),
    ]);
    model.hold_at = Some(hold_at);
    let bus = I2cBus::new(model, [2, 1]);
    let clears = std::cell::Cell::new(0);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut watch = Box::pin(bus.serve_watch::<TestClock>(|| {
        clears.set(clears.get() + 1);
        bus.with_block(Model::release);
    }));
    assert!(watch.as_mut().poll(&mut cx).is_pending());
    let sample = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
    let gauge = register_read(bq27500::ADDRESS, 0x08, 2);
    let mut first = Box::pin(bus.run(bus.client(0).unwrap(), sample));
    let mut second = Box::pin(bus.run(bus.client(1).unwrap(), gauge));
    assert!(first.as_mut().poll(&mut cx).is_pending());
    assert!(second.as_mut().poll(&mut cx).is_pending());
    let mut results = (None, None);
    let mut ended_at_us = 0;
    for step in 0..2_000u64 {
        let now = step * 10;
        set_now(now);
        if hold_us.is_some_and(|hold| now >= hold) {
            bus.with_block(Model::release);
        }
        pump(&bus);
        assert!(watch.as_mut().poll(&mut cx).is_pending());
        pump(&bus);
        if results.0.is_none() {
            if let Poll::Ready(result) = first.as_mut().poll(&mut cx) {
                results.0 = Some(result);
                ended_at_us = now;
            }
        }
        if results.1.is_none() {
            if let Poll::Ready(result) = second.as_mut().poll(&mut cx) {
                results.1 = Some(result);
            }
        }
        if results.0.is_some() && results.1.is_some() {
            break;
        }
    }
    drop(watch);
    let model = bus.with_block(|m| core::mem::replace(m, Model::new(Vec::new())));
    Watched {
        first: results.0.expect("the first script never ended"),
        second: results.1.expect("the second script never ended"),
        clears: clears.get(),
        ended_at_us,
        model,
    }
}

/// A device holding SCL past the script's deadline at its repeated START (stalled, looked at every
/// `STRETCH_REARM_US`) ends the script with `Stretched` at its deadline (wire time + 200 µs per
/// event: 210 + 11 × 200 µs), the lines cleared once, the block reset; the script behind it then
/// runs and ends with its readings. Before deadlines, the script stayed on the bus until its
/// client's timeout (`I2cPort`), and `Failure` had no `Stretched`.
#[test]
fn a_stretch_past_the_deadline_ends_the_script_as_stretched_and_the_next_runs() {
    let sample = register_read(hmc5883l::ADDRESS, hmc5883l::reg::DATA_X_MSB, 6);
    let deadline = u64::from(deadline_us(&sample));
    assert_eq!(deadline, 210 + 11 * 200);
    for (hold_at, operation) in [(2, 0), (5, 0)] {
        let watched = under_watch(hold_at, None);
        assert_eq!(
            watched.first,
            Err(ScriptError {
                operation,
                failure: Failure::Stretched
            }),
            "held at wire byte {hold_at}"
        );
        // Ended at its deadline, within the test's 10 µs step.
        assert!(
            (deadline..deadline + 10).contains(&watched.ended_at_us),
            "{}",
            watched.ended_at_us
        );
        assert_eq!(watched.clears, 1);
        let gauge = Device::new(bq27500::ADDRESS);
        assert_eq!(
            watched.second.expect("the next script runs").of(0),
            expected_bytes(&gauge, 0x08, 2)
        );
        assert!(watched.model.access.contains(&Reset));
    }
}

/// A stretch within the deadline (1 ms at the repeated START, or mid-read) is waited out: the
/// script ends with its readings, nothing is cleared, and the next script runs.
#[test]
fn a_stretch_within_the_deadline_completes() {
    for hold_at in [2, 5] {
        let watched = under_watch(hold_at, Some(1_000));
        let device = Device::new(hmc5883l::ADDRESS);
        assert_eq!(
            watched.first.expect("within its deadline").of(0),
            expected_bytes(&device, hmc5883l::reg::DATA_X_MSB, 6)
        );
        assert!(watched.ended_at_us >= 1_000);
        assert_eq!(watched.clears, 0);
        assert!(watched.second.is_ok());
        assert!(
            watched.model.violations.is_empty(),
            "{:?}",
            watched.model.violations
        );
    }
}
