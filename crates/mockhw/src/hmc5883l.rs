//! HMC5883L twin: registers and behaviour from the Honeywell datasheet (Form #900405 Rev E), through the register
//! map in [`magcal_driver::hmc5883l::regs`].
//!
//! Modelled: the identification registers `'H' '4' '3'`; the register pointer, which moves on after each byte,
//! returns to X MSB (0x03) once all six data registers have been read, and wraps from 12 to 0; the reset values
//! (15 Hz, gain 1090 LSB/G, single-measurement mode); continuous mode at the seven output rates, single
//! measurements (after which the chip idles); the eight gains, with the datasheet's quirk that the first
//! measurement after a gain change still uses the previous gain; the 12-bit output, big-endian in the order X, Z,
//! Y, with -4096 in a channel that overflowed; RDY (set when new data is in, cleared when the data is read) and
//! LOCK (set while only some of the six data registers have been read; the outputs do not update then).

use magcal_driver::hmc5883l::regs;

use crate::bus::Twin;
use crate::sampling::{Env, Ticker, counts};

/// Time of one single measurement, s (the datasheet's 6 ms).
const SINGLE_MEASUREMENT_S: f64 = 0.006;

/// LSB per gauss of each gain setting.
const LSB_PER_GAUSS: [f64; 8] = [1370.0, 1090.0, 820.0, 660.0, 440.0, 390.0, 330.0, 230.0];

/// Output rates of the DO settings, Hz (setting 7 is reserved; the twin treats it as 75 Hz).
const RATES_HZ: [f64; 8] = [0.75, 1.5, 3.0, 7.5, 15.0, 30.0, 75.0, 75.0];

pub(crate) struct Hmc5883lTwin {
    regs: [u8; 0x0D],
    pointer: u8,
    ticker: Ticker,
    single_due_s: Option<f64>,
    /// The gain the next measurement uses (it lags a gain change by one measurement).
    gain_in_use: usize,
    /// Which of the six data bytes have been read since the last update.
    data_read: [bool; 6],
}

impl Hmc5883lTwin {
    pub(crate) fn new() -> Hmc5883lTwin {
        let mut regs_init = [0u8; 0x0D];
        regs_init[usize::from(regs::CONFIG_A)] = 0x10;
        regs_init[usize::from(regs::CONFIG_B)] = 0x20;
        regs_init[usize::from(regs::MODE)] = regs::MODE_SINGLE;
        regs_init[usize::from(regs::ID_A)..=usize::from(regs::ID_C)]
            .copy_from_slice(&regs::ID_VALUE);
        Hmc5883lTwin {
            regs: regs_init,
            pointer: 0,
            ticker: Ticker::default(),
            // At power-on the chip is in single-measurement mode and takes one measurement.
            single_due_s: Some(SINGLE_MEASUREMENT_S),
            gain_in_use: 1,
            data_read: [false; 6],
        }
    }

    fn reg(&self, r: u8) -> u8 {
        self.regs[usize::from(r)]
    }

    fn gain_setting(&self) -> usize {
        usize::from(self.reg(regs::CONFIG_B) >> regs::CONFIG_B_GN_SHIFT)
    }

    fn rate_hz(&self) -> f64 {
        RATES_HZ[usize::from((self.reg(regs::CONFIG_A) >> regs::CONFIG_A_DO_SHIFT) & 0b111)]
    }

    fn apply_mode(&mut self, now_s: f64) {
        match self.reg(regs::MODE) & 0b11 {
            regs::MODE_CONTINUOUS => {
                self.ticker.start(now_s, 1.0 / self.rate_hz());
                self.single_due_s = None;
            }
            regs::MODE_SINGLE => {
                self.ticker.stop();
                self.single_due_s = Some(now_s + SINGLE_MEASUREMENT_S);
            }
            _ => {
                self.ticker.stop();
                self.single_due_s = None;
            }
        }
    }

    fn locked(&self) -> bool {
        self.data_read.iter().any(|r| *r) && !self.data_read.iter().all(|r| *r)
    }

    fn measure(&mut self, env: &Env<'_>, t_s: f64) {
        let m = env.measure(t_s);
        let lsb_ut = 100.0 / LSB_PER_GAUSS[self.gain_in_use];
        self.gain_in_use = self.gain_setting();
        if self.locked() {
            return;
        }
        if !m.stuck {
            // Register order X, Z, Y.
            for (slot, axis) in [0, 2, 1].into_iter().enumerate() {
                let (c, overflow) = counts(m.raw_ut[axis], lsb_ut, -2048, 2047);
                let value = if overflow { regs::OVERFLOW } else { c as i16 };
                let r = usize::from(regs::DATA_X_MSB) + 2 * slot;
                self.regs[r..r + 2].copy_from_slice(&value.to_be_bytes());
            }
        }
        self.regs[usize::from(regs::STATUS)] |= regs::STATUS_RDY;
        self.data_read = [false; 6];
    }

    fn next_pointer(p: u8) -> u8 {
        match p {
            regs::DATA_Y_LSB => regs::DATA_X_MSB,
            regs::ID_C => regs::CONFIG_A,
            _ => p + 1,
        }
    }
}

impl Twin for Hmc5883lTwin {
    fn update(&mut self, env: &Env<'_>) {
        if let Some((t, _)) = self.ticker.take(env.now_s) {
            self.measure(env, t);
        }
        if let Some(due) = self.single_due_s
            && env.now_s >= due
        {
            self.measure(env, due);
            self.single_due_s = None;
            self.regs[usize::from(regs::MODE)] = regs::MODE_IDLE;
        }
    }

    fn write(&mut self, env: &Env<'_>, bytes: &[u8]) {
        let Some((&sub, data)) = bytes.split_first() else {
            return;
        };
        self.pointer = sub.min(regs::ID_C);
        for &value in data {
            match self.pointer {
                regs::CONFIG_A => {
                    self.regs[usize::from(regs::CONFIG_A)] = value;
                    if self.ticker.is_running() {
                        self.ticker.start(env.now_s, 1.0 / self.rate_hz());
                    }
                }
                regs::CONFIG_B => self.regs[usize::from(regs::CONFIG_B)] = value,
                regs::MODE => {
                    self.regs[usize::from(regs::MODE)] = value;
                    self.data_read = [false; 6];
                    self.apply_mode(env.now_s);
                }
                _ => {} // read-only: ignored
            }
            self.pointer = Self::next_pointer(self.pointer);
        }
    }

    fn read(&mut self, _env: &Env<'_>, buf: &mut [u8]) {
        for out in buf.iter_mut() {
            let p = self.pointer;
            *out = if p == regs::STATUS {
                self.reg(p) | if self.locked() { regs::STATUS_LOCK } else { 0 }
            } else {
                self.reg(p)
            };
            if (regs::DATA_X_MSB..=regs::DATA_Y_LSB).contains(&p) {
                self.data_read[usize::from(p - regs::DATA_X_MSB)] = true;
                self.regs[usize::from(regs::STATUS)] &= !regs::STATUS_RDY;
            }
            self.pointer = Self::next_pointer(p);
        }
        if self.data_read.iter().all(|r| *r) {
            self.data_read = [false; 6];
        }
    }

    fn peek(&self, reg: u8) -> u8 {
        self.regs.get(usize::from(reg)).copied().unwrap_or(0)
    }
}
