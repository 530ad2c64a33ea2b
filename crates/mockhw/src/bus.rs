//! A simulated chip on its I2C bus: the [`embedded_hal::i2c::I2c`] implementation every twin sits behind.

use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, Operation};
use magcal_driver::ChipKind;

use crate::clock::VirtualClock;
use crate::fault::{Fault, Faults, NACK};
use crate::sampling::{Env, SharedBench};
use crate::{hmc5883l, lis2mdl, lis3mdl, mmc5983ma, qmc5883l};

/// The register behaviour of one chip: what a write or read of its registers does.
pub(crate) trait Twin {
    /// Brings the chip up to `env.now_s`: conversions that finished since the last call.
    fn update(&mut self, env: &Env<'_>);
    /// One write: the sub-address byte, then data bytes (possibly none: a pointer move).
    fn write(&mut self, env: &Env<'_>, bytes: &[u8]);
    /// One read from the register pointer.
    fn read(&mut self, env: &Env<'_>, buf: &mut [u8]);
    /// A register as it stands, without the side effects of a bus read.
    fn peek(&self, reg: u8) -> u8;
    /// Sets the sensing element's own offset that SET/RESET removes, µT; `false` for chips without SET/RESET.
    fn set_bridge_offset_ut(&mut self, _offset_ut: [f64; 3]) -> bool {
        false
    }
}

/// Default bus clock: fast-mode I2C.
pub const DEFAULT_BUS_HZ: u32 = 400_000;

/// One of the supported chips, simulated at register level on its own I2C bus, sampling a shared
/// [`Bench`](magcal_sim::bench::Bench) at the times its output data rate says.
///
/// Every transaction takes its bit time on the [`VirtualClock`] (9 bit times per byte, address bytes included), so a
/// driver that polls a status register sees time pass as on a real bus. A transaction to another address is not
/// acknowledged, as on a real bus with nobody there. Faults ([`Fault`]) are injected from given times on.
pub struct SimChip {
    kind: ChipKind,
    address: u8,
    twin: Box<dyn Twin>,
    bench: SharedBench,
    clock: VirtualClock,
    faults: Faults,
    bus_hz: u32,
    transactions: u64,
}

impl std::fmt::Debug for SimChip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimChip")
            .field("kind", &self.kind)
            .field("address", &self.address)
            .field("now_s", &self.clock.now_s())
            .field("transactions", &self.transactions)
            .finish_non_exhaustive()
    }
}

impl SimChip {
    /// A powered-up `kind` at its default address, in the reset state its datasheet gives.
    pub fn new(kind: ChipKind, bench: SharedBench, clock: VirtualClock) -> SimChip {
        let twin: Box<dyn Twin> = match kind {
            ChipKind::Lis3mdl => Box::new(lis3mdl::Lis3mdlTwin::new()),
            ChipKind::Lis2mdl => Box::new(lis2mdl::Lis2mdlTwin::new()),
            ChipKind::Qmc5883l => Box::new(qmc5883l::Qmc5883lTwin::new()),
            ChipKind::Hmc5883l => Box::new(hmc5883l::Hmc5883lTwin::new()),
            ChipKind::Mmc5983ma => Box::new(mmc5983ma::Mmc5983maTwin::new()),
        };
        SimChip {
            kind,
            address: kind.default_address(),
            twin,
            bench,
            clock,
            faults: Faults::default(),
            bus_hz: DEFAULT_BUS_HZ,
            transactions: 0,
        }
    }

    /// The same chip answering at `address` (strapped differently).
    pub fn with_address(mut self, address: u8) -> SimChip {
        self.address = address;
        self
    }

    /// The same chip on a bus clocked at `bus_hz`.
    pub fn with_bus_hz(mut self, bus_hz: u32) -> SimChip {
        self.bus_hz = bus_hz.max(1);
        self
    }

    /// The same chip with a bridge offset (µT, sensor axes): the sensing element's own offset, which keeps its sign
    /// when SET/RESET flips the field's (MMC5983MA). `None` for chips without SET/RESET.
    pub fn with_bridge_offset_ut(mut self, offset_ut: [f64; 3]) -> Option<SimChip> {
        self.twin.set_bridge_offset_ut(offset_ut).then_some(self)
    }

    /// Adds a fault.
    pub fn inject(&mut self, fault: Fault) {
        self.faults.push(fault);
    }

    /// Which chip this is.
    pub fn kind(&self) -> ChipKind {
        self.kind
    }

    /// The 7-bit address it answers.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// The bench it samples.
    pub fn bench(&self) -> &SharedBench {
        &self.bench
    }

    /// Its clock.
    pub fn clock(&self) -> &VirtualClock {
        &self.clock
    }

    /// Transactions seen so far (failed ones included).
    pub fn transactions(&self) -> u64 {
        self.transactions
    }

    /// Register `reg` as it stands now, without the side effects a bus read would have (for tests).
    pub fn peek(&mut self, reg: u8) -> u8 {
        let env = Env::new(self.clock.now_s(), &self.bench, &self.faults);
        self.twin.update(&env);
        self.twin.peek(reg)
    }

    /// Bit time of `bytes` bytes plus start and stop conditions, ns.
    fn bus_time_ns(&self, bytes: usize) -> u64 {
        let bits = bytes as u64 * 9 + 2;
        bits * 1_000_000_000 / u64::from(self.bus_hz)
    }
}

impl ErrorType for SimChip {
    type Error = ErrorKind;
}

impl I2c for SimChip {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), ErrorKind> {
        self.transactions += 1;
        // The address byte is sent once per direction change (a repeated start re-sends it).
        let mut bytes = 1;
        let mut last_is_read = None;
        for op in operations.iter() {
            let is_read = matches!(op, Operation::Read(_));
            if last_is_read.is_some_and(|r| r != is_read) {
                bytes += 1;
            }
            last_is_read = Some(is_read);
            bytes += match op {
                Operation::Read(buf) => buf.len(),
                Operation::Write(data) => data.len(),
            };
        }
        self.clock.advance_ns(self.bus_time_ns(bytes));
        let now_s = self.clock.now_s();
        if address != self.address || self.faults.transaction_fails(now_s) {
            return Err(NACK);
        }
        let ignore_writes = self.faults.ignores_writes(now_s);
        let env = Env::new(now_s, &self.bench, &self.faults);
        self.twin.update(&env);
        for op in operations.iter_mut() {
            match op {
                Operation::Write(data) if ignore_writes => {
                    // The pointer moves; the data is dropped.
                    self.twin.write(&env, &data[..data.len().min(1)]);
                }
                Operation::Write(data) => self.twin.write(&env, data),
                Operation::Read(buf) => self.twin.read(&env, buf),
            }
        }
        Ok(())
    }
}
