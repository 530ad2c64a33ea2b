//! MMC5983MA twin: registers and behaviour from the MEMSIC datasheet (Rev A, 2019), through the register map in
//! [`magcal_driver::mmc5983ma::regs`].
//!
//! Modelled: the product id; the write-only control registers (they read as 0); single magnetic (TM_M) and
//! temperature (TM_T) measurements taking the bandwidth's measurement time (8/4/2/0.5 ms; the datasheet gives no
//! separate figure for the temperature, so the twin uses the same); continuous mode at 1–1000 Hz; Meas_M_Done and
//! Meas_T_Done, set when a measurement ends and cleared by writing 1 or by the next command; SW_RST; the 18-bit
//! unsigned output around the null field 131072 (16384 counts/G), clipped at its limits, with bits 17:10, 9:2 and
//! the two low bits of each axis in XYZout2; the temperature output (-75 °C at 0, 0.8 °C/LSB); and the SET/RESET
//! magnetisation: after SET the field part of the output is +H, after RESET −H, while the bridge offset keeps its
//! sign (so (set − reset)/2 is the field and (set + reset)/2 the offset). Auto_SR_en keeps the sensor SET.

use magcal_driver::mmc5983ma::regs;

use crate::bus::Twin;
use crate::sampling::{Env, Ticker, counts};

/// Output rates of Cm_freq 1–7, Hz.
const RATES_HZ: [f64; 7] = [1.0, 10.0, 20.0, 50.0, 100.0, 200.0, 1000.0];

/// Measurement time of each bandwidth setting, s.
const MEASUREMENT_S: [f64; 4] = [0.008, 0.004, 0.002, 0.0005];

pub(crate) struct Mmc5983maTwin {
    /// Readable registers 0x00–0x08 and the product id; control registers are kept apart (write-only).
    out: [u8; 0x30],
    control: [u8; 4],
    pointer: u8,
    ticker: Ticker,
    magnetic_due_s: Option<f64>,
    temperature_due_s: Option<f64>,
    /// +1 after SET, −1 after RESET.
    polarity: f64,
    bridge_offset_ut: [f64; 3],
}

impl Mmc5983maTwin {
    pub(crate) fn new() -> Mmc5983maTwin {
        let mut twin = Mmc5983maTwin {
            out: [0; 0x30],
            control: [0; 4],
            pointer: 0,
            ticker: Ticker::default(),
            magnetic_due_s: None,
            temperature_due_s: None,
            polarity: 1.0,
            bridge_offset_ut: [0.0; 3],
        };
        twin.reset();
        twin
    }

    fn reset(&mut self) {
        self.out = [0; 0x30];
        self.out[usize::from(regs::PRODUCT_ID)] = regs::PRODUCT_ID_VALUE;
        self.out[usize::from(regs::STATUS)] = regs::STATUS_OTP_READ_DONE;
        self.control = [0; 4];
        self.ticker.stop();
        self.magnetic_due_s = None;
        self.temperature_due_s = None;
    }

    fn measurement_s(&self) -> f64 {
        MEASUREMENT_S[usize::from(self.control[1] & 0b11)]
    }

    fn apply_control_2(&mut self, now_s: f64) {
        let c2 = self.control[2];
        let freq = usize::from(c2 & 0b111);
        if c2 & regs::CONTROL_2_CMM_EN != 0 && freq != 0 {
            self.ticker.start(now_s, 1.0 / RATES_HZ[freq - 1]);
        } else {
            self.ticker.stop();
        }
    }

    fn command(&mut self, now_s: f64, value: u8) {
        // Setting bits are kept; command bits act once.
        self.control[0] = value & (regs::CONTROL_0_AUTO_SR_EN | regs::CONTROL_0_INT_MEAS_DONE_EN);
        let measurement_s = self.measurement_s();
        let status = &mut self.out[usize::from(regs::STATUS)];
        if value & regs::CONTROL_0_SET != 0 {
            self.polarity = 1.0;
        }
        if value & regs::CONTROL_0_RESET != 0 {
            self.polarity = -1.0;
        }
        if value & regs::CONTROL_0_TM_M != 0 {
            *status &= !regs::STATUS_MEAS_M_DONE;
            self.magnetic_due_s = Some(now_s + measurement_s);
        }
        if value & regs::CONTROL_0_TM_T != 0 {
            *status &= !regs::STATUS_MEAS_T_DONE;
            self.temperature_due_s = Some(now_s + measurement_s);
        }
    }

    fn magnetic(&mut self, env: &Env<'_>, t_s: f64) {
        let m = env.measure(t_s);
        if !m.stuck {
            let polarity = if self.control[0] & regs::CONTROL_0_AUTO_SR_EN != 0 {
                1.0
            } else {
                self.polarity
            };
            let lsb_ut = 100.0 / f64::from(regs::COUNTS_PER_GAUSS_18);
            let code: [u32; 3] = std::array::from_fn(|axis| {
                let field = polarity * m.raw_ut[axis] + self.bridge_offset_ut[axis];
                let (c, _) = counts(field, lsb_ut, -regs::NULL_FIELD_18, regs::NULL_FIELD_18 - 1);
                (c + regs::NULL_FIELD_18) as u32
            });
            for axis in 0..3 {
                self.out[2 * axis] = (code[axis] >> 10) as u8;
                self.out[2 * axis + 1] = (code[axis] >> 2) as u8;
            }
            self.out[usize::from(regs::XYZOUT2)] =
                ((code[0] & 3) << 6 | (code[1] & 3) << 4 | (code[2] & 3) << 2) as u8;
        }
        self.out[usize::from(regs::STATUS)] |= regs::STATUS_MEAS_M_DONE;
    }
}

impl Twin for Mmc5983maTwin {
    fn update(&mut self, env: &Env<'_>) {
        if let Some((t, _)) = self.ticker.take(env.now_s) {
            self.magnetic(env, t);
        }
        if let Some(due) = self.magnetic_due_s
            && env.now_s >= due
        {
            self.magnetic(env, due);
            self.magnetic_due_s = None;
        }
        if let Some(due) = self.temperature_due_s
            && env.now_s >= due
        {
            let raw = ((env.temperature_c(due) - f64::from(regs::TEMP_ZERO_C))
                / f64::from(regs::TEMP_C_PER_LSB))
            .round()
            .clamp(0.0, 255.0);
            self.out[usize::from(regs::TOUT)] = raw as u8;
            self.out[usize::from(regs::STATUS)] |= regs::STATUS_MEAS_T_DONE;
            self.temperature_due_s = None;
        }
    }

    fn write(&mut self, env: &Env<'_>, bytes: &[u8]) {
        let Some((&sub, data)) = bytes.split_first() else {
            return;
        };
        self.pointer = sub & 0x3F;
        for &value in data {
            match self.pointer {
                regs::STATUS => {
                    // Writing 1 clears a done flag.
                    let clear = value & (regs::STATUS_MEAS_M_DONE | regs::STATUS_MEAS_T_DONE);
                    self.out[usize::from(regs::STATUS)] &= !clear;
                }
                regs::CONTROL_0 => self.command(env.now_s, value),
                regs::CONTROL_1 if value & regs::CONTROL_1_SW_RST != 0 => self.reset(),
                regs::CONTROL_1 => self.control[1] = value,
                regs::CONTROL_2 => {
                    self.control[2] = value;
                    self.apply_control_2(env.now_s);
                }
                regs::CONTROL_3 => self.control[3] = value,
                _ => {} // read-only: ignored
            }
            self.pointer = (self.pointer + 1) & 0x3F;
        }
    }

    fn read(&mut self, _env: &Env<'_>, buf: &mut [u8]) {
        for out in buf.iter_mut() {
            // The control registers are write-only: they read as 0.
            *out = self.out[usize::from(self.pointer)];
            self.pointer = (self.pointer + 1) & 0x3F;
        }
    }

    fn peek(&self, reg: u8) -> u8 {
        self.out.get(usize::from(reg)).copied().unwrap_or(0)
    }

    fn set_bridge_offset_ut(&mut self, offset_ut: [f64; 3]) -> bool {
        self.bridge_offset_ut = offset_ut;
        true
    }
}
