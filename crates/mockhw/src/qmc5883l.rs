//! QMC5883L twin: registers and behaviour from the QST datasheet (QMC5883L-Datasheet-1.0), through the register map
//! in [`magcal_driver::qmc5883l::regs`].
//!
//! Modelled: the chip id register; pointer increment, rolling over within 0x00–0x06 when ROL_PNT is set; SOFT_RST
//! (every register back to its default: standby); standby and continuous modes at 10/50/100/200 Hz; the ±2 G
//! (12000 LSB/G) and ±8 G (3000 LSB/G) ranges; DRDY, cleared by reading any data register; OVL when an axis leaves
//! the 16-bit output range (the output then saturates); DOR when a sample was not read before the next; the
//! relative temperature (about 100 LSB/°C around an uncalibrated zero).

use magcal_driver::qmc5883l::regs;

use crate::bus::Twin;
use crate::sampling::{Env, Ticker, counts};

/// The temperature this part reads 0 at, °C. The datasheet leaves the zero uncalibrated ("relative only"); the twin
/// picks one, so only differences come out right, as on the real part.
const TEMP_OUTPUT_ZERO_C: f64 = 5.0;

pub(crate) struct Qmc5883lTwin {
    regs: [u8; 0x10],
    pointer: u8,
    ticker: Ticker,
}

impl Qmc5883lTwin {
    pub(crate) fn new() -> Qmc5883lTwin {
        let mut twin = Qmc5883lTwin {
            regs: [0; 0x10],
            pointer: 0,
            ticker: Ticker::default(),
        };
        twin.soft_reset();
        twin
    }

    fn reg(&self, r: u8) -> u8 {
        self.regs[usize::from(r)]
    }

    fn soft_reset(&mut self) {
        self.regs = [0; 0x10];
        self.regs[usize::from(regs::CHIP_ID)] = regs::CHIP_ID_VALUE;
        self.ticker.stop();
    }

    fn rate_hz(&self) -> f64 {
        [10.0, 50.0, 100.0, 200.0]
            [usize::from((self.reg(regs::CONTROL_1) >> regs::CONTROL_1_ODR_SHIFT) & 0b11)]
    }

    fn lsb_ut(&self) -> f64 {
        match (self.reg(regs::CONTROL_1) >> regs::CONTROL_1_RNG_SHIFT) & 0b11 {
            0b00 => 100.0 / 12000.0,
            _ => 100.0 / 3000.0,
        }
    }

    fn apply_control_1(&mut self, now_s: f64) {
        if self.reg(regs::CONTROL_1) & 0b11 == regs::CONTROL_1_MODE_CONTINUOUS {
            self.ticker.start(now_s, 1.0 / self.rate_hz());
        } else {
            self.ticker.stop();
        }
    }

    fn convert(&mut self, env: &Env<'_>, t_s: f64, skipped: bool) {
        let m = env.measure(t_s);
        let mut overflow = false;
        if !m.stuck {
            let lsb = self.lsb_ut();
            for axis in 0..3 {
                let (c, clipped) = counts(m.raw_ut[axis], lsb, i16::MIN.into(), i16::MAX.into());
                overflow |= clipped;
                let r = usize::from(regs::DATA_X_LSB) + 2 * axis;
                self.regs[r..r + 2].copy_from_slice(&(c as i16).to_le_bytes());
            }
            let t = ((m.temp_c - TEMP_OUTPUT_ZERO_C) * f64::from(regs::TEMP_LSB_PER_C))
                .round()
                .clamp(i16::MIN.into(), i16::MAX.into()) as i16;
            let r = usize::from(regs::TOUT_LSB);
            self.regs[r..r + 2].copy_from_slice(&t.to_le_bytes());
        }
        let status = &mut self.regs[usize::from(regs::STATUS)];
        let dor = skipped || *status & regs::STATUS_DRDY != 0;
        *status = regs::STATUS_DRDY
            | if overflow { regs::STATUS_OVL } else { 0 }
            | if dor { regs::STATUS_DOR } else { 0 };
    }

    fn next_pointer(&self, p: u8) -> u8 {
        let rollover = self.reg(regs::CONTROL_2) & regs::CONTROL_2_ROL_PNT != 0;
        if rollover && p == regs::STATUS {
            regs::DATA_X_LSB
        } else {
            (p + 1) & 0x0F
        }
    }
}

impl Twin for Qmc5883lTwin {
    fn update(&mut self, env: &Env<'_>) {
        if let Some((t, n)) = self.ticker.take(env.now_s) {
            self.convert(env, t, n > 1);
        }
    }

    fn write(&mut self, env: &Env<'_>, bytes: &[u8]) {
        let Some((&sub, data)) = bytes.split_first() else {
            return;
        };
        self.pointer = sub & 0x0F;
        for &value in data {
            match self.pointer {
                regs::CONTROL_1 => {
                    self.regs[usize::from(regs::CONTROL_1)] = value;
                    self.apply_control_1(env.now_s);
                }
                regs::CONTROL_2 if value & regs::CONTROL_2_SOFT_RST != 0 => self.soft_reset(),
                regs::CONTROL_2 | regs::SET_RESET_PERIOD => {
                    self.regs[usize::from(self.pointer)] = value;
                }
                _ => {} // read-only: ignored
            }
            self.pointer = self.next_pointer(self.pointer);
        }
    }

    fn read(&mut self, _env: &Env<'_>, buf: &mut [u8]) {
        let mut read_data = false;
        for out in buf.iter_mut() {
            *out = self.reg(self.pointer);
            read_data |= self.pointer <= regs::DATA_Z_MSB;
            self.pointer = self.next_pointer(self.pointer);
        }
        if read_data {
            self.regs[usize::from(regs::STATUS)] = 0;
        }
    }

    fn peek(&self, reg: u8) -> u8 {
        self.regs.get(usize::from(reg)).copied().unwrap_or(0)
    }
}
