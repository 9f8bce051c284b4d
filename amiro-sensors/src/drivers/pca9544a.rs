//! NXP PCA9544A four-channel I2C multiplexer: how the AMiRo reaches several VCNL4020s that all
//! answer at 0x13.
//!
//! The part has one control register, written with a single byte: bit 2 enables the downstream
//! channel, bits 1..0 select it (`0x04 | channel`); 0x00 disconnects every channel. Bits 7..4 read
//! back the four interrupt inputs. Address 0x70 | A2A1A0; the AMiRo boards strap A2..A0 high
//! (0x77), one mux per bus: DiWheelDrive I2C2, PowerManagement I2C1 and I2C2.
//!
//! [`Pca9544a::select`] writes the control byte and hands out a [`MuxedBus`]: an `I2c` that
//! reaches the devices behind that channel and mutably borrows the mux while it lives, so no other
//! code can switch the channel under a sensor driver mid-conversation.

use embedded_hal::i2c::{ErrorType, I2c, Operation};

use super::Error;

/// The address with A2..A0 high, as on every AMiRo board.
pub const AMIRO_ADDRESS: u8 = 0x77;
/// Control-register bit that connects the selected channel.
pub const ENABLE: u8 = 0x04;

/// A downstream channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Channel {
    /// Channel 0 (SD0/SC0).
    Ch0,
    /// Channel 1.
    Ch1,
    /// Channel 2.
    Ch2,
    /// Channel 3.
    Ch3,
}

impl Channel {
    /// All four, in order.
    pub const ALL: [Channel; 4] = [Channel::Ch0, Channel::Ch1, Channel::Ch2, Channel::Ch3];

    /// The channel number 0..=3.
    pub const fn number(self) -> u8 {
        match self {
            Channel::Ch0 => 0,
            Channel::Ch1 => 1,
            Channel::Ch2 => 2,
            Channel::Ch3 => 3,
        }
    }

    /// The channel with number `n`, if there is one.
    pub const fn from_number(n: u8) -> Option<Channel> {
        match n {
            0 => Some(Channel::Ch0),
            1 => Some(Channel::Ch1),
            2 => Some(Channel::Ch2),
            3 => Some(Channel::Ch3),
            _ => None,
        }
    }

    /// The control byte that connects this channel.
    pub const fn control_byte(self) -> u8 {
        ENABLE | self.number()
    }
}

/// What the control register says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Control {
    /// The connected channel, `None` when disabled.
    pub selected: Option<Channel>,
    /// The four interrupt inputs (bit n = INTn asserted).
    pub interrupts: u8,
}

impl Control {
    /// Decodes a control-register byte.
    pub const fn from_byte(byte: u8) -> Self {
        let selected = if byte & ENABLE != 0 {
            Channel::from_number(byte & 0x03)
        } else {
            None
        };
        Self {
            selected,
            interrupts: byte >> 4,
        }
    }
}

/// A PCA9544A on a bus.
#[derive(Debug, Clone)]
pub struct Pca9544a<I2C> {
    i2c: I2C,
    address: u8,
}

impl<I2C> Pca9544a<I2C> {
    /// A mux at [`AMIRO_ADDRESS`]. Does no I/O.
    pub const fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, AMIRO_ADDRESS)
    }

    /// A mux at another address (0x70..=0x77).
    pub const fn with_address(i2c: I2C, address: u8) -> Self {
        Self { i2c, address }
    }

    /// The mux's address.
    pub const fn address(&self) -> u8 {
        self.address
    }
}

impl<I2C: I2c> Pca9544a<I2C> {
    /// Connects `channel` and returns a bus that reaches the devices behind it.
    pub fn select(&mut self, channel: Channel) -> Result<MuxedBus<'_, I2C>, Error<I2C::Error>> {
        self.i2c.write(self.address, &[channel.control_byte()])?;
        Ok(MuxedBus { mux: self, channel })
    }

    /// Disconnects every channel.
    pub fn disable(&mut self) -> Result<(), Error<I2C::Error>> {
        self.i2c.write(self.address, &[0x00])?;
        Ok(())
    }

    /// Reads the control register.
    pub fn control(&mut self) -> Result<Control, Error<I2C::Error>> {
        let mut byte = [0u8];
        self.i2c.read(self.address, &mut byte)?;
        Ok(Control::from_byte(byte[0]))
    }

    /// The upstream bus, for devices that sit beside the mux rather than behind it.
    pub fn bus_mut(&mut self) -> &mut I2C {
        &mut self.i2c
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }
}

/// The bus as seen behind one connected channel.
///
/// Transfers go straight through (the mux is transparent once a channel is connected); the borrow
/// of the mux keeps the channel from changing while this exists.
#[derive(Debug)]
pub struct MuxedBus<'a, I2C> {
    mux: &'a mut Pca9544a<I2C>,
    channel: Channel,
}

impl<I2C> MuxedBus<'_, I2C> {
    /// The connected channel.
    pub fn channel(&self) -> Channel {
        self.channel
    }
}

impl<I2C: I2c> ErrorType for MuxedBus<'_, I2C> {
    type Error = I2C::Error;
}

impl<I2C: I2c> I2c for MuxedBus<'_, I2C> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.mux.i2c.transaction(address, operations)
    }

    // Inlined, so the bus's own `read`/`write`/`write_read` are called with the driver's slices
    // (their lengths fixed at the driver's call, where the execution-time analysis reads them).
    #[inline(always)]
    fn read(&mut self, address: u8, read: &mut [u8]) -> Result<(), Self::Error> {
        self.mux.i2c.read(address, read)
    }

    #[inline(always)]
    fn write(&mut self, address: u8, write: &[u8]) -> Result<(), Self::Error> {
        self.mux.i2c.write(address, write)
    }

    #[inline(always)]
    fn write_read(
        &mut self,
        address: u8,
        write: &[u8],
        read: &mut [u8],
    ) -> Result<(), Self::Error> {
        self.mux.i2c.write_read(address, write, read)
    }
}

/// The mux's transaction as a script operation: the control byte that connects `channel`,
/// written to the mux at `address` (its own transaction: the part connects at the STOP).
pub fn select_op(
    script: &mut crate::script::Script,
    address: u8,
    channel: Channel,
) -> Result<(), crate::script::BuildError> {
    script.write(address, &[channel.control_byte()])?;
    Ok(())
}
