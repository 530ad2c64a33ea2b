//! LIS3MDL twin: registers, reset values, output data rates and full scales from the ST datasheet (DocID024204),
//! through the register map in [`magcal_driver::lis3mdl::regs`].
//!
//! Modelled: WHO_AM_I; the sub-address auto-increment bit (without it a multi-byte read repeats the register);
//! SOFT_RST (configuration back to reset values); continuous, single and power-down modes; the DO rates and the
//! fast-ODR rates fixed by the operating mode; the four full scales; the endianness bit; STATUS_REG with new-data and
//! overrun bits, cleared by reading the outputs; outputs clipped at the 16-bit limits (the chip has no saturation
//! flag in the data path); the temperature output (8 LSB/°C, 0 at 25 °C) while TEMP_EN is set.

use magcal_driver::lis3mdl::regs;

use crate::bus::Twin;
use crate::sampling::{Env, Ticker, counts, word_bytes};

/// Time of one single conversion in the twin, s (a conversion at the fastest DO rate).
const SINGLE_CONVERSION_S: f64 = 1.0 / 80.0;

pub(crate) struct Lis3mdlTwin {
    regs: [u8; 0x40],
    pointer: u8,
    auto_increment: bool,
    ticker: Ticker,
    /// When a single conversion finishes, s.
    single_due_s: Option<f64>,
}

const RESET: [(u8, u8); 5] = [
    (regs::CTRL_REG1, 0x10),
    (regs::CTRL_REG2, 0x00),
    (regs::CTRL_REG3, 0x03),
    (regs::CTRL_REG4, 0x00),
    (regs::CTRL_REG5, 0x00),
];

impl Lis3mdlTwin {
    pub(crate) fn new() -> Lis3mdlTwin {
        let mut twin = Lis3mdlTwin {
            regs: [0; 0x40],
            pointer: 0,
            auto_increment: false,
            ticker: Ticker::default(),
            single_due_s: None,
        };
        twin.regs[usize::from(regs::WHO_AM_I)] = regs::WHO_AM_I_VALUE;
        twin.soft_reset();
        twin
    }

    fn reg(&self, r: u8) -> u8 {
        self.regs[usize::from(r)]
    }

    fn soft_reset(&mut self) {
        for (r, v) in RESET {
            self.regs[usize::from(r)] = v;
        }
        self.ticker.stop();
        self.single_due_s = None;
    }

    /// The output data rate the control registers select, Hz.
    fn rate_hz(&self) -> f64 {
        let ctrl1 = self.reg(regs::CTRL_REG1);
        if ctrl1 & regs::CTRL1_FAST_ODR != 0 {
            return match (ctrl1 >> regs::CTRL1_OM_SHIFT) & 0b11 {
                0b00 => 1000.0,
                0b01 => 560.0,
                0b10 => 300.0,
                _ => 155.0,
            };
        }
        [0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0]
            [usize::from((ctrl1 >> regs::CTRL1_DO_SHIFT) & 0b111)]
    }

    /// µT per LSB at the selected full scale.
    fn lsb_ut(&self) -> f64 {
        let lsb_per_gauss = [6842.0, 3421.0, 2281.0, 1711.0]
            [usize::from((self.reg(regs::CTRL_REG2) >> regs::CTRL2_FS_SHIFT) & 0b11)];
        100.0 / lsb_per_gauss
    }

    /// Starts or stops conversions as CTRL_REG3 says.
    fn apply_mode(&mut self, now_s: f64) {
        match self.reg(regs::CTRL_REG3) & 0b11 {
            regs::CTRL3_MD_CONTINUOUS => {
                self.ticker.start(now_s, 1.0 / self.rate_hz());
                self.single_due_s = None;
            }
            regs::CTRL3_MD_SINGLE => {
                self.ticker.stop();
                self.single_due_s = Some(now_s + SINGLE_CONVERSION_S);
            }
            _ => {
                self.ticker.stop();
                self.single_due_s = None;
            }
        }
    }

    fn convert(&mut self, env: &Env<'_>, t_s: f64, overrun: bool) {
        let m = env.measure(t_s);
        if !m.stuck {
            let big_endian = self.reg(regs::CTRL_REG4) & regs::CTRL4_BLE != 0;
            let lsb = self.lsb_ut();
            for axis in 0..3 {
                let (c, _) = counts(m.raw_ut[axis], lsb, i16::MIN.into(), i16::MAX.into());
                let b = word_bytes(c as i16, big_endian);
                let r = usize::from(regs::OUT_X_L) + 2 * axis;
                self.regs[r..r + 2].copy_from_slice(&b);
            }
            if self.reg(regs::CTRL_REG1) & regs::CTRL1_TEMP_EN != 0 {
                let raw = ((m.temp_c - f64::from(regs::TEMP_ZERO_C))
                    * f64::from(regs::TEMP_LSB_PER_C))
                .round()
                .clamp(i16::MIN.into(), i16::MAX.into()) as i16;
                let b = word_bytes(raw, big_endian);
                let r = usize::from(regs::TEMP_OUT_L);
                self.regs[r..r + 2].copy_from_slice(&b);
            }
        }
        let status = &mut self.regs[usize::from(regs::STATUS_REG)];
        let overrun = overrun || *status & regs::STATUS_ZYXDA != 0;
        *status = 0x0F | if overrun { 0xF0 } else { 0 };
    }
}

impl Twin for Lis3mdlTwin {
    fn update(&mut self, env: &Env<'_>) {
        if let Some((t, n)) = self.ticker.take(env.now_s) {
            self.convert(env, t, n > 1);
        }
        if let Some(due) = self.single_due_s
            && env.now_s >= due
        {
            self.convert(env, due, false);
            self.single_due_s = None;
            let ctrl3 = &mut self.regs[usize::from(regs::CTRL_REG3)];
            *ctrl3 |= regs::CTRL3_MD_POWER_DOWN;
        }
    }

    fn write(&mut self, env: &Env<'_>, bytes: &[u8]) {
        let Some((&sub, data)) = bytes.split_first() else {
            return;
        };
        self.auto_increment = sub & regs::AUTO_INCREMENT != 0;
        self.pointer = sub & 0x3F;
        for &value in data {
            let r = self.pointer;
            match r {
                regs::CTRL_REG1 | regs::CTRL_REG4 | regs::CTRL_REG5 => {
                    self.regs[usize::from(r)] = value;
                    if r == regs::CTRL_REG1 && self.ticker.is_running() {
                        self.ticker.start(env.now_s, 1.0 / self.rate_hz());
                    }
                }
                regs::CTRL_REG2 => {
                    if value & regs::CTRL2_SOFT_RST != 0 {
                        self.soft_reset();
                    } else {
                        self.regs[usize::from(r)] = value & !regs::CTRL2_REBOOT;
                    }
                }
                regs::CTRL_REG3 => {
                    self.regs[usize::from(r)] = value;
                    self.apply_mode(env.now_s);
                }
                regs::INT_CFG | regs::INT_THS_L | regs::INT_THS_H => {
                    self.regs[usize::from(r)] = value;
                }
                _ => {} // read-only or reserved: ignored
            }
            if self.auto_increment {
                self.pointer = (self.pointer + 1) & 0x3F;
            }
        }
    }

    fn read(&mut self, _env: &Env<'_>, buf: &mut [u8]) {
        let mut read_outputs = false;
        for out in buf.iter_mut() {
            *out = self.reg(self.pointer);
            read_outputs |= (regs::OUT_X_L..=regs::OUT_Z_H).contains(&self.pointer);
            if self.auto_increment {
                self.pointer = (self.pointer + 1) & 0x3F;
            }
        }
        if read_outputs {
            self.regs[usize::from(regs::STATUS_REG)] = 0;
        }
    }

    fn peek(&self, reg: u8) -> u8 {
        self.regs.get(usize::from(reg)).copied().unwrap_or(0)
    }
}
