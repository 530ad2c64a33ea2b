//! LIS2MDL twin: registers, reset values, rates and sensitivity from the ST datasheet (DS12144), through the
//! register map in [`magcal_driver::lis2mdl::regs`].
//!
//! Modelled: WHO_AM_I; automatic sub-address increment; SOFT_RST (configuration and the hard-iron offset registers
//! back to zero); continuous, single and idle modes at 10/20/50/100 Hz; the fixed 1.5 mG/LSB output with the
//! hard-iron offset registers subtracted (output = measured − offset, both at 1.5 mG/LSB) and clipped at the 16-bit
//! limits; the endianness bit; STATUS_REG with new-data and overrun bits, cleared by reading the outputs; the
//! temperature output (8 LSB/°C, 0 at 25 °C).

use magcal_driver::lis2mdl::regs;

use crate::bus::Twin;
use crate::sampling::{Env, Ticker, counts, word_bytes};

/// Time of one single conversion in the twin, s (one period at the fastest rate).
const SINGLE_CONVERSION_S: f64 = 1.0 / 100.0;

pub(crate) struct Lis2mdlTwin {
    regs: [u8; 0x80],
    pointer: u8,
    ticker: Ticker,
    single_due_s: Option<f64>,
}

impl Lis2mdlTwin {
    pub(crate) fn new() -> Lis2mdlTwin {
        let mut twin = Lis2mdlTwin {
            regs: [0; 0x80],
            pointer: 0,
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
        for r in regs::OFFSET_X_REG_L..=regs::OFFSET_Z_REG_H {
            self.regs[usize::from(r)] = 0;
        }
        self.regs[usize::from(regs::CFG_REG_A)] = regs::CFG_A_MD_IDLE;
        self.regs[usize::from(regs::CFG_REG_B)] = 0;
        self.regs[usize::from(regs::CFG_REG_C)] = 0;
        self.ticker.stop();
        self.single_due_s = None;
    }

    fn rate_hz(&self) -> f64 {
        [10.0, 20.0, 50.0, 100.0]
            [usize::from((self.reg(regs::CFG_REG_A) >> regs::CFG_A_ODR_SHIFT) & 0b11)]
    }

    fn big_endian(&self) -> bool {
        self.reg(regs::CFG_REG_C) & regs::CFG_C_BLE != 0
    }

    fn apply_mode(&mut self, now_s: f64) {
        match self.reg(regs::CFG_REG_A) & 0b11 {
            regs::CFG_A_MD_CONTINUOUS => {
                self.ticker.start(now_s, 1.0 / self.rate_hz());
                self.single_due_s = None;
            }
            regs::CFG_A_MD_SINGLE => {
                self.ticker.stop();
                self.single_due_s = Some(now_s + SINGLE_CONVERSION_S);
            }
            _ => {
                self.ticker.stop();
                self.single_due_s = None;
            }
        }
    }

    /// The hard-iron offset registers, counts (always little-endian two's complement).
    fn offset_counts(&self) -> [i32; 3] {
        std::array::from_fn(|axis| {
            let r = usize::from(regs::OFFSET_X_REG_L) + 2 * axis;
            i32::from(i16::from_le_bytes([self.regs[r], self.regs[r + 1]]))
        })
    }

    fn convert(&mut self, env: &Env<'_>, t_s: f64, overrun: bool) {
        let m = env.measure(t_s);
        if !m.stuck {
            let big_endian = self.big_endian();
            let offset = self.offset_counts();
            for axis in 0..3 {
                let (measured, _) = counts(m.raw_ut[axis], f64::from(regs::LSB_UT), -65536, 65535);
                let out = (measured - offset[axis]).clamp(i16::MIN.into(), i16::MAX.into()) as i16;
                let r = usize::from(regs::OUTX_L_REG) + 2 * axis;
                self.regs[r..r + 2].copy_from_slice(&word_bytes(out, big_endian));
            }
            let raw = ((m.temp_c - f64::from(regs::TEMP_ZERO_C)) * f64::from(regs::TEMP_LSB_PER_C))
                .round()
                .clamp(i16::MIN.into(), i16::MAX.into()) as i16;
            let r = usize::from(regs::TEMP_OUT_L_REG);
            self.regs[r..r + 2].copy_from_slice(&word_bytes(raw, big_endian));
        }
        let status = &mut self.regs[usize::from(regs::STATUS_REG)];
        let overrun = overrun || *status & regs::STATUS_ZYXDA != 0;
        *status = 0x0F | if overrun { 0xF0 } else { 0 };
    }
}

impl Twin for Lis2mdlTwin {
    fn update(&mut self, env: &Env<'_>) {
        if let Some((t, n)) = self.ticker.take(env.now_s) {
            self.convert(env, t, n > 1);
        }
        if let Some(due) = self.single_due_s
            && env.now_s >= due
        {
            self.convert(env, due, false);
            self.single_due_s = None;
            self.regs[usize::from(regs::CFG_REG_A)] |= regs::CFG_A_MD_IDLE;
        }
    }

    fn write(&mut self, env: &Env<'_>, bytes: &[u8]) {
        let Some((&sub, data)) = bytes.split_first() else {
            return;
        };
        self.pointer = sub & 0x7F;
        for &value in data {
            let r = self.pointer;
            match r {
                regs::CFG_REG_A => {
                    if value & regs::CFG_A_SOFT_RST != 0 {
                        self.soft_reset();
                    } else {
                        self.regs[usize::from(r)] = value & !regs::CFG_A_REBOOT;
                        self.apply_mode(env.now_s);
                    }
                }
                regs::OFFSET_X_REG_L..=regs::OFFSET_Z_REG_H
                | regs::CFG_REG_B
                | regs::CFG_REG_C
                | regs::INT_CTRL_REG
                | regs::INT_THS_L_REG
                | regs::INT_THS_H_REG => self.regs[usize::from(r)] = value,
                _ => {} // read-only or reserved: ignored
            }
            self.pointer = (self.pointer + 1) & 0x7F;
        }
    }

    fn read(&mut self, _env: &Env<'_>, buf: &mut [u8]) {
        let mut read_outputs = false;
        for out in buf.iter_mut() {
            *out = self.reg(self.pointer);
            read_outputs |= (regs::OUTX_L_REG..=regs::OUTZ_H_REG).contains(&self.pointer);
            self.pointer = (self.pointer + 1) & 0x7F;
        }
        if read_outputs {
            self.regs[usize::from(regs::STATUS_REG)] = 0;
        }
    }

    fn peek(&self, reg: u8) -> u8 {
        self.regs.get(usize::from(reg)).copied().unwrap_or(0)
    }
}
