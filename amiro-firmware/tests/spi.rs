//! The SPI master against a model SPI block: set-up, full-duplex exchange, and a block whose flags
//! never come (not clocked, as in a chip whose clock tree failed) ending in a bounded timeout.
use std::cell::{Cell, RefCell};
use std::collections::VecDeque;

use amiro_firmware::bxcan::Registers;
use amiro_firmware::spi::{self, divider_code, Error, Master, POLLS};
use embedded_hal::spi::{Mode, Phase, Polarity, SpiBus, MODE_0, MODE_3};

const CR1: usize = 0x00;
const SR: usize = 0x08;
const DR: usize = 0x0C;

/// A block that answers each byte with the next one of `replies` (or the byte inverted), unless dead.
#[derive(Default)]
struct Block {
    cr1: Cell<u32>,
    sent: RefCell<Vec<u8>>,
    replies: RefCell<VecDeque<u8>>,
    rx: Cell<Option<u8>>,
    dead: bool,
    overrun: Cell<bool>,
    sr_reads: Cell<u32>,
    frames16: Cell<u32>,
    /// A mode fault pending: the hardware cleared MSTR and SPE and shows MODF until CR1 is written.
    mode_fault: Cell<bool>,
}

impl Registers for &Block {
    fn read(&self, offset: usize) -> u32 {
        match offset {
            SR => {
                self.sr_reads.set(self.sr_reads.get() + 1);
                if self.dead {
                    return 0;
                }
                let mut sr = 1 << 1; // TXE
                if self.rx.get().is_some() {
                    sr |= 1;
                }
                if self.overrun.get() {
                    sr |= 1 << 6;
                }
                if self.mode_fault.get() {
                    sr |= 1 << 5;
                }
                sr
            }
            DR => {
                self.overrun.set(false);
                self.rx.take().map(u32::from).unwrap_or(0)
            }
            CR1 => self.cr1.get(),
            _ => 0,
        }
    }

    fn write(&self, offset: usize, value: u32) {
        match offset {
            CR1 => {
                self.mode_fault.set(false);
                self.cr1.set(value);
            }
            // A 16-bit frame (CR1 DFF) is recorded as its two bytes, the high one first (MSB
            // first on the wire).
            DR if !self.dead && self.cr1.get() & 1 << 11 != 0 => {
                assert_eq!(
                    self.cr1.get() & 1 << 6,
                    1 << 6,
                    "a frame written while enabled"
                );
                self.frames16.set(self.frames16.get() + 1);
                self.sent
                    .borrow_mut()
                    .extend([(value >> 8) as u8, value as u8]);
                self.rx.set(Some(0));
            }
            DR if !self.dead => {
                let byte = value as u8;
                self.sent.borrow_mut().push(byte);
                let reply = self.replies.borrow_mut().pop_front().unwrap_or(!byte);
                self.rx.set(Some(reply));
            }
            _ => {}
        }
    }
}

#[test]
fn set_up_as_master_with_software_slave_select_at_the_fastest_allowed_rate() {
    let block = Block::default();
    let _bus = Master::new(&block, 36_000_000, 9_000_000, MODE_0);
    let cr1 = block.cr1.get();
    assert_eq!(cr1 & 0b100, 0b100, "MSTR");
    assert_eq!(cr1 & (0b11 << 8), 0b11 << 8, "SSM and SSI");
    assert_eq!(cr1 & 1 << 6, 1 << 6, "enabled");
    assert_eq!(cr1 >> 3 & 0b111, 1, "36 MHz / 4 = 9 MHz");
    assert_eq!(cr1 & 0b11, 0, "mode 0");
    let block = Block::default();
    let _bus = Master::new(&block, 8_000_000, 9_000_000, MODE_3);
    assert_eq!(block.cr1.get() & 0b11, 0b11, "mode 3: CPOL and CPHA");
    assert_eq!(
        block.cr1.get() >> 3 & 0b111,
        0,
        "8 MHz / 2 is the fastest there is"
    );
    let mode = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnSecondTransition,
    };
    let block = Block::default();
    let _bus = Master::new(&block, 36_000_000, 2_250_000, mode);
    assert_eq!(block.cr1.get() & 0b11, 0b01);
    assert_eq!(block.cr1.get() >> 3 & 0b111, 3, "36 MHz / 16 = 2.25 MHz");
    assert_eq!(
        divider_code(72_000_000, 100_000),
        7,
        "the slowest divider at most"
    );
}

#[test]
fn bytes_are_exchanged_in_order_in_every_form() {
    let block = Block::default();
    block.replies.borrow_mut().extend([0xD3, 0x32, 0x11]);
    let mut bus = Master::new(&block, 36_000_000, 9_000_000, MODE_0);
    let mut read = [0u8; 2];
    bus.transfer(&mut read, &[0x8F, 0x00, 0x55]).unwrap();
    assert_eq!(read, [0xD3, 0x32]);
    assert_eq!(*block.sent.borrow(), [0x8F, 0x00, 0x55]);
    let mut words = [0x01, 0x02];
    bus.transfer_in_place(&mut words).unwrap();
    assert_eq!(words, [0xFE, 0xFD]);
    bus.write(&[0xAA]).unwrap();
    let mut one = [0u8; 1];
    bus.read(&mut one).unwrap();
    assert_eq!(one, [0xFF], "a read clocks out zeros");
    bus.flush().unwrap();
}

#[test]
fn a_block_whose_flags_never_come_times_out_after_the_bound() {
    let block = Block {
        dead: true,
        ..Block::default()
    };
    let mut bus = Master::new(&block, 36_000_000, 9_000_000, MODE_0);
    assert_eq!(bus.write(&[1, 2, 3]), Err(Error::Timeout));
    assert_eq!(
        block.sr_reads.get(),
        POLLS,
        "one byte's wait, then the error"
    );
    block.sr_reads.set(0);
    let mut read = [0u8; 4];
    assert_eq!(bus.read(&mut read), Err(Error::Timeout));
    assert_eq!(block.sr_reads.get(), POLLS);
}

#[test]
fn an_overrun_is_reported_and_cleared() {
    let block = Block::default();
    let mut bus = Master::new(&block, 36_000_000, 9_000_000, MODE_0);
    block.overrun.set(true);
    assert_eq!(bus.write(&[1]), Err(Error::Overrun));
    assert!(!block.overrun.get(), "reading DR then SR cleared it");
    assert_eq!(bus.write(&[1]), Ok(()));
    let _ = spi::SPI1;
}

#[test]
fn a_mode_fault_leaves_the_block_a_master_again() {
    let block = Block::default();
    let mut bus = Master::new(&block, 36_000_000, 9_000_000, MODE_0);
    let set_up = block.cr1.get();
    // The fault clears MSTR and SPE (RM0008 §25.3.10).
    block.cr1.set(set_up & !(1 << 2 | 1 << 6));
    block.mode_fault.set(true);
    assert_eq!(bus.write(&[1]), Err(Error::ModeFault));
    assert_eq!(block.cr1.get(), set_up, "MSTR and SPE set again");
    assert_eq!(bus.write(&[2]), Ok(()));
}

/// A chip-select pin that records every level it is driven to.
#[derive(Default)]
struct Select<'a> {
    levels: Option<&'a RefCell<Vec<bool>>>,
}

impl embedded_hal::digital::ErrorType for Select<'_> {
    type Error = core::convert::Infallible;
}

impl embedded_hal::digital::OutputPin for Select<'_> {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        if let Some(levels) = self.levels {
            levels.borrow_mut().push(false);
        }
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Self::Error> {
        if let Some(levels) = self.levels {
            levels.borrow_mut().push(true);
        }
        Ok(())
    }
}

#[test]
fn a_device_write_sends_every_byte_between_the_select_falling_and_rising() {
    use embedded_hal::spi::SpiDevice;
    let block = Block::default();
    let levels = RefCell::new(Vec::new());
    let bus = Master::new(&block, 36_000_000, 2_250_000, MODE_0);
    let mut device = spi::Device::new(
        bus,
        Select {
            levels: Some(&levels),
        },
    );
    assert_eq!(*levels.borrow(), [true], "released at set-up");
    let frame: Vec<u8> = (0..108).map(|i| (i * 7) as u8).collect();
    // The unread bytes of a transmit-only stream overrun the receiver: no error, cleared at the end.
    block.overrun.set(true);
    device.write(&frame).unwrap();
    assert_eq!(*block.sent.borrow(), frame, "every byte, in order");
    assert_eq!(
        block.frames16.get(),
        54,
        "as 16-bit frames, half the writes"
    );
    assert_eq!(block.cr1.get() & 1 << 11, 0, "back to 8-bit frames");
    assert_eq!(block.cr1.get() & 1 << 6, 1 << 6, "enabled again");
    assert_eq!(
        *levels.borrow(),
        [true, false, true],
        "one select, one latch"
    );
    assert!(!block.overrun.get(), "the overrun cleared (DR, then SR)");
    assert_eq!(block.rx.get(), None, "the last received byte read away");
    // The full-duplex exchange after it starts clean.
    block.replies.borrow_mut().push_back(0x5A);
    let mut read = [0u8; 1];
    device.transfer(&mut read, &[0x80]).unwrap();
    assert_eq!(read, [0x5A]);
}

#[test]
fn an_odd_number_of_bytes_goes_as_bytes() {
    use embedded_hal::spi::SpiDevice;
    let block = Block::default();
    let mut device = spi::Device::new(
        Master::new(&block, 36_000_000, 2_250_000, MODE_0),
        Select::default(),
    );
    device.write(&[1, 2, 3]).unwrap();
    assert_eq!(*block.sent.borrow(), [1, 2, 3]);
    assert_eq!(block.frames16.get(), 0);
}

#[test]
fn a_device_write_to_a_dead_block_times_out_and_releases_the_select() {
    use embedded_hal::spi::SpiDevice;
    let block = Block {
        dead: true,
        ..Block::default()
    };
    let levels = RefCell::new(Vec::new());
    let mut device = spi::Device::new(
        Master::new(&block, 36_000_000, 2_250_000, MODE_0),
        Select {
            levels: Some(&levels),
        },
    );
    assert_eq!(
        device.write(&[1, 2, 3]),
        Err(spi::DeviceError::Bus(Error::Timeout))
    );
    assert_eq!(
        block.sr_reads.get(),
        POLLS,
        "one byte's wait, then the error"
    );
    assert!(block.sent.borrow().is_empty());
    assert_eq!(levels.borrow().last(), Some(&true), "the select released");
}

#[test]
fn a_device_refuses_a_delay_operation() {
    use embedded_hal::spi::{Operation, SpiDevice};
    let block = Block::default();
    let mut device = spi::Device::new(
        Master::new(&block, 36_000_000, 2_250_000, MODE_0),
        Select::default(),
    );
    assert_eq!(
        device.transaction(&mut [Operation::Write(&[1]), Operation::DelayNs(10)]),
        Err(spi::DeviceError::NoDelay)
    );
    assert_eq!(*block.sent.borrow(), [1], "the write before it ran");
}
