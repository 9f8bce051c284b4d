//! Simulated HMC5883L magnetometer (I2C 0x1E).

use super::{RegisterDevice, RegisterPointer, SimBus};
use crate::drivers::hmc5883l::{self, reg};
use crate::motion::trig::{sin_cos, ONE, TURN_NRAD};

/// A simulated HMC5883L.
///
/// Pattern: a 20 µT horizontal field turning one full circle every 360 samples (the robot slowly
/// spinning) and a −40 µT vertical field. A sample is taken each time the host starts reading at
/// the X MSB register while the part is in continuous or single mode (single mode then drops to
/// idle, as the part does). Encoded at the gain in CRB; an axis beyond ±2047 digits reads −4096.
/// The register pointer behaves as the datasheet says: it auto-increments, wraps from 0x08 to
/// 0x03 and from 0x0C to 0x00. [`SimHmc5883l::set_field`] replaces the pattern with a field from
/// outside (a world's robot turning in the lab's field).
#[derive(Debug, Clone)]
pub struct SimHmc5883l {
    config_a: u8,
    config_b: u8,
    mode: u8,
    pointer: RegisterPointer,
    samples: u32,
    /// X, Z, Y digits, register order.
    latched: [i16; 3],
    input_nt: Option<[i32; 3]>,
}

impl SimHmc5883l {
    /// At power-on: CRA 0x10, CRB 0x20, MODE 0x01 (single, then idle).
    pub const fn new() -> Self {
        Self {
            config_a: 0x10,
            config_b: 0x20,
            mode: 0x01,
            pointer: RegisterPointer::new(),
            samples: 0,
            latched: [0; 3],
            input_nt: None,
        }
    }

    /// From now on the part measures this field (nanotesla, x y z); `None` goes back to the
    /// pattern.
    pub fn set_field(&mut self, nanotesla: Option<[i32; 3]>) {
        self.input_nt = nanotesla;
    }

    /// CRA, CRB, MODE as the host last wrote them.
    pub const fn registers(&self) -> [u8; 3] {
        [self.config_a, self.config_b, self.mode]
    }

    /// Whether the host configured the AMiRo set-up (CRA 0x74, CRB 0xA0, continuous).
    pub const fn is_configured_for_amiro(&self) -> bool {
        self.config_a == hmc5883l::CONFIG_A_AMIRO
            && self.config_b == hmc5883l::Gain::Ga4_7.config_b()
            && self.mode & 0x03 == hmc5883l::MODE_CONTINUOUS
    }

    /// Samples taken so far.
    pub const fn samples(&self) -> u32 {
        self.samples
    }

    /// The simulated field at sample `n` in nanotesla, X, Y, Z.
    pub const fn field_at(n: u32) -> [i32; 3] {
        let angle = (n % 360) as i64 * (TURN_NRAD / 360);
        let (sin, cos) = sin_cos(angle);
        [
            (20_000 * cos / ONE) as i32,
            (20_000 * sin / ONE) as i32,
            -40_000,
        ]
    }

    fn lsb_per_gauss(&self) -> i64 {
        match self.config_b >> 5 {
            0 => 1370,
            1 => 1090,
            2 => 820,
            3 => 660,
            4 => 440,
            5 => 390,
            6 => 330,
            _ => 230,
        }
    }

    fn measure(&mut self) {
        if self.mode & 0x02 != 0 {
            return; // idle: the data registers keep the last measurement
        }
        let [x, y, z] = match self.input_nt {
            Some(field) => field,
            None => Self::field_at(self.samples),
        };
        let gain = self.lsb_per_gauss();
        let encode = |nanotesla: i32| {
            let digits = crate::drivers::div_round(i64::from(nanotesla) * gain, 100_000);
            if (-2048..=2047).contains(&digits) {
                digits as i16
            } else {
                hmc5883l::OVERFLOW
            }
        };
        self.latched = [encode(x), encode(z), encode(y)];
        self.samples = self.samples.wrapping_add(1);
        if self.mode & 0x03 == 0x01 {
            self.mode = (self.mode & !0x03) | 0x03;
        }
    }
}

impl Default for SimHmc5883l {
    fn default() -> Self {
        Self::new()
    }
}

impl RegisterDevice for SimHmc5883l {
    const ADDRESS: u8 = hmc5883l::ADDRESS;

    fn pointer(&mut self) -> &mut RegisterPointer {
        &mut self.pointer
    }

    fn read_started(&mut self, register: u8) {
        if register == reg::DATA_X_MSB {
            self.measure();
        }
    }

    fn write_register(&mut self, register: u8, byte: u8) {
        match register {
            reg::CONFIG_A => self.config_a = byte & 0x7F,
            reg::CONFIG_B => self.config_b = byte & 0xE0,
            reg::MODE => self.mode = byte & 0x83,
            _ => {}
        }
    }

    fn read_register(&mut self, register: u8) -> u8 {
        match register {
            reg::CONFIG_A => self.config_a,
            reg::CONFIG_B => self.config_b,
            reg::MODE => self.mode,
            p @ 0x03..=0x08 => {
                let i = usize::from(p - 0x03);
                let word = self.latched.get(i / 2).copied().unwrap_or(0).to_be_bytes();
                word[i % 2]
            }
            reg::STATUS => 0x01,
            0x0A => b'H',
            0x0B => b'4',
            0x0C => b'3',
            _ => 0,
        }
    }

    fn next_register(&self, register: u8) -> u8 {
        match register {
            0x08 => 0x03,
            p if p >= 0x0C => 0x00,
            p => p + 1,
        }
    }
}

impl SimBus<SimHmc5883l> {
    /// The simulated magnetometer.
    pub const fn magnetometer(&self) -> &SimHmc5883l {
        &self.target
    }

    /// The simulated magnetometer, to feed it a field.
    pub fn magnetometer_mut(&mut self) -> &mut SimHmc5883l {
        &mut self.target
    }
}
