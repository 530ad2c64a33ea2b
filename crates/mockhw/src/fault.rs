//! Faults a simulated chip or its bus can be told to show, from a given (virtual) time on.

use std::fmt;
use std::str::FromStr;

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};

/// One fault, starting at `at_s` on the chip's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// The next `count` bus transactions from `at_s` on are not acknowledged (a loose wire, a brown-out).
    Nack {
        /// Start, s.
        at_s: f64,
        /// How many transactions fail.
        count: u32,
    },
    /// The chip is gone from the bus from `at_s` on: every transaction is not acknowledged.
    DropBus {
        /// Start, s.
        at_s: f64,
    },
    /// From `at_s` on, register writes are acknowledged but not applied (a write-protected or wedged chip); the
    /// register pointer still moves, so reads work.
    IgnoreWrites {
        /// Start, s.
        at_s: f64,
    },
    /// From `at_s` on the output registers stop updating, while data-ready still comes at the output rate.
    StuckData {
        /// Start, s.
        at_s: f64,
    },
    /// A magnet near the sensor: `field_ut` (sensor axes) adds to the field from `at_s` for `duration_s`. Strong
    /// enough, it drives the chip out of its range.
    Magnet {
        /// Start, s.
        at_s: f64,
        /// How long, s.
        duration_s: f64,
        /// The added field, sensor axes, µT.
        field_ut: [f64; 3],
    },
}

impl Fault {
    /// When the fault starts, s.
    pub fn at_s(&self) -> f64 {
        match *self {
            Fault::Nack { at_s, .. }
            | Fault::DropBus { at_s }
            | Fault::IgnoreWrites { at_s }
            | Fault::StuckData { at_s }
            | Fault::Magnet { at_s, .. } => at_s,
        }
    }
}

impl fmt::Display for Fault {
    /// The form [`FromStr`] reads: `nack@T:N`, `drop@T`, `ignore-writes@T`, `stuck@T`, `magnet@T:DUR:X,Y,Z`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Fault::Nack { at_s, count } => write!(f, "nack@{at_s}:{count}"),
            Fault::DropBus { at_s } => write!(f, "drop@{at_s}"),
            Fault::IgnoreWrites { at_s } => write!(f, "ignore-writes@{at_s}"),
            Fault::StuckData { at_s } => write!(f, "stuck@{at_s}"),
            Fault::Magnet {
                at_s,
                duration_s,
                field_ut: [x, y, z],
            } => write!(f, "magnet@{at_s}:{duration_s}:{x},{y},{z}"),
        }
    }
}

/// A fault description that does not parse.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FaultSyntax(pub String);

impl fmt::Display for FaultSyntax {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "bad fault {:?}: expected nack@T:COUNT, drop@T, ignore-writes@T, stuck@T or magnet@T:DURATION:X,Y,Z \
             (times in s on the chip's clock, field in µT)",
            self.0
        )
    }
}

impl std::error::Error for FaultSyntax {}

impl FromStr for Fault {
    type Err = FaultSyntax;

    fn from_str(s: &str) -> Result<Fault, FaultSyntax> {
        let bad = || FaultSyntax(s.to_owned());
        let (kind, rest) = s.split_once('@').ok_or_else(bad)?;
        let mut parts = rest.split(':');
        let number = |p: Option<&str>| -> Result<f64, FaultSyntax> {
            p.and_then(|p| p.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(bad)
        };
        let at_s = number(parts.next())?;
        let fault = match kind.trim() {
            "nack" => Fault::Nack {
                at_s,
                count: parts
                    .next()
                    .and_then(|c| c.trim().parse().ok())
                    .ok_or_else(bad)?,
            },
            "drop" => Fault::DropBus { at_s },
            "ignore-writes" => Fault::IgnoreWrites { at_s },
            "stuck" => Fault::StuckData { at_s },
            "magnet" => {
                let duration_s = number(parts.next())?;
                let xyz: Vec<f64> = parts
                    .next()
                    .ok_or_else(bad)?
                    .split(',')
                    .map(|v| v.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad())?;
                let field_ut: [f64; 3] = xyz.try_into().map_err(|_| bad())?;
                Fault::Magnet {
                    at_s,
                    duration_s,
                    field_ut,
                }
            }
            _ => return Err(bad()),
        };
        if parts.next().is_some() {
            return Err(bad());
        }
        Ok(fault)
    }
}

/// The faults of one chip, with what they have done so far.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Faults {
    faults: Vec<Fault>,
    /// Per fault, how many transactions it has failed.
    failed: Vec<u32>,
}

/// The error a missing acknowledgement gives: nobody answered the address.
pub(crate) const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

impl Faults {
    pub(crate) fn push(&mut self, fault: Fault) {
        self.faults.push(fault);
        self.failed.push(0);
    }

    /// Whether the transaction at `now_s` fails, counting it against the fault that fails it.
    pub(crate) fn transaction_fails(&mut self, now_s: f64) -> bool {
        for (fault, failed) in self.faults.iter().zip(self.failed.iter_mut()) {
            match *fault {
                Fault::DropBus { at_s } if now_s >= at_s => return true,
                Fault::Nack { at_s, count } if now_s >= at_s && *failed < count => {
                    *failed += 1;
                    return true;
                }
                _ => {}
            }
        }
        false
    }

    pub(crate) fn ignores_writes(&self, now_s: f64) -> bool {
        self.faults
            .iter()
            .any(|f| matches!(*f, Fault::IgnoreWrites { at_s } if now_s >= at_s))
    }

    pub(crate) fn stuck(&self, now_s: f64) -> bool {
        self.faults
            .iter()
            .any(|f| matches!(*f, Fault::StuckData { at_s } if now_s >= at_s))
    }

    /// The field of the magnets near the sensor at `t_s`, sensor axes, µT.
    pub(crate) fn magnet_ut(&self, t_s: f64) -> [f64; 3] {
        let mut sum = [0.0; 3];
        for f in &self.faults {
            if let Fault::Magnet {
                at_s,
                duration_s,
                field_ut,
            } = *f
                && t_s >= at_s
                && t_s < at_s + duration_s
            {
                (0..3).for_each(|k| sum[k] += field_ut[k]);
            }
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_round_trip_through_text() {
        for text in [
            "nack@5:3",
            "drop@12.5",
            "ignore-writes@0",
            "stuck@2",
            "magnet@1:0.5:3000,0,-20",
        ] {
            let f: Fault = text.parse().unwrap();
            assert_eq!(f.to_string(), text);
        }
        for bad in [
            "nack@5",
            "drop",
            "magnet@1:2:3,4",
            "fire@1",
            "stuck@-1",
            "drop@1:2",
        ] {
            let e = bad.parse::<Fault>().unwrap_err();
            assert!(e.to_string().contains("nack@T:COUNT"), "{e}");
        }
    }

    #[test]
    fn nacks_are_counted_and_a_dropped_bus_stays_dropped() {
        let mut f = Faults::default();
        f.push(Fault::Nack {
            at_s: 1.0,
            count: 2,
        });
        assert!(!f.transaction_fails(0.5));
        assert!(f.transaction_fails(1.0));
        assert!(f.transaction_fails(1.1));
        assert!(!f.transaction_fails(1.2));
        f.push(Fault::DropBus { at_s: 3.0 });
        assert!(!f.transaction_fails(2.9));
        assert!((0..10).all(|_| f.transaction_fails(3.0)));
    }

    #[test]
    fn magnets_add_while_they_last() {
        let mut f = Faults::default();
        f.push(Fault::Magnet {
            at_s: 1.0,
            duration_s: 1.0,
            field_ut: [100.0, 0.0, 0.0],
        });
        f.push(Fault::StuckData { at_s: 5.0 });
        assert_eq!(f.magnet_ut(0.9), [0.0; 3]);
        assert_eq!(f.magnet_ut(1.5), [100.0, 0.0, 0.0]);
        assert_eq!(f.magnet_ut(2.0), [0.0; 3]);
        assert!(!f.stuck(4.9) && f.stuck(5.0));
    }
}
