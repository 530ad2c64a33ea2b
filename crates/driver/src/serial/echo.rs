//! Verifying a calibration write by the firmware's `Cal1:`/`Cal2:` echo.
//!
//! Firmware built on Adafruit's calibration sketches prints what it holds every so often:
//! `Cal1:` (accelerometer and gyro offsets, hard iron, field) and `Cal2:` (the soft-iron matrix
//! S, row-major, so `S₀₁` appears twice). MotionCal marks a calibration as confirmed once both
//! lines match what it sent. [`EchoCheck`] does the same, with a tolerance taken from how many
//! decimals the firmware printed: half a unit of the last printed digit, plus a relative 1e-6
//! for f32 arithmetic in the firmware's float printing.
//!
//! Echoes printed before the firmware took the packet still show its previous calibration,
//! and how many arrive depends on latency, so they cannot be told apart by count. They are told
//! apart by content: the firmware prints the same values until it takes the packet. For each
//! kind, the reference is the last echo read before sending when the caller knows it, else
//! the first mismatching echo after sending (presumed stale). A mismatching echo equal to the
//! reference is skipped as stale; one that differs from it shows that the firmware changed its
//! calibration to something else than what was sent, and fails the verification at once.
//! A garbled echo is let pass once ([`GARBLED_ECHOES_TOLERATED`]); the next fails.
//!
//! Past the timeout the verification fails on what was seen, in this order: a mismatching
//! echo that was not known to be the previous calibration, an echo that kept showing the
//! known previous calibration (the packet was not taken), a garbled echo, nothing.

use std::fmt;

use super::counts::GarbageKind;
use super::motioncal::{CAL1_LEN, CAL2_LEN, Echo, EchoKind};
use super::packet::CalibrationPacket;

/// Garbled echoes of each kind that are let pass before the verification fails.
pub const GARBLED_ECHOES_TOLERATED: u32 = 1;

/// Relative slack added to the printing tolerance for f32 rounding in the firmware.
const RELATIVE_SLACK: f64 = 1e-6;

const CAL1_FIELDS: [&str; CAL1_LEN] = [
    "accel_zero_g_m_s2[0]",
    "accel_zero_g_m_s2[1]",
    "accel_zero_g_m_s2[2]",
    "gyro_zero_rate_rad_s[0]",
    "gyro_zero_rate_rad_s[1]",
    "gyro_zero_rate_rad_s[2]",
    "hard_iron_ut[0]",
    "hard_iron_ut[1]",
    "hard_iron_ut[2]",
    "field_ut",
];

const CAL2_FIELDS: [&str; CAL2_LEN] = [
    "soft_iron[0][0]",
    "soft_iron[0][1]",
    "soft_iron[0][2]",
    "soft_iron[1][0]",
    "soft_iron[1][1]",
    "soft_iron[1][2]",
    "soft_iron[2][0]",
    "soft_iron[2][1]",
    "soft_iron[2][2]",
];

/// One echoed value that is not what was sent.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldMismatch {
    /// Which value, e.g. `hard_iron_ut[1]` or `soft_iron[0][2]`.
    pub field: &'static str,
    /// What was sent (the packet's f32).
    pub sent: f64,
    /// What the firmware printed.
    pub echoed: f64,
    /// The largest difference accepted for this print.
    pub tolerance: f64,
}

/// Why the firmware's echo does not confirm the calibration.
#[derive(Clone, Debug, PartialEq)]
pub enum VerifyFailure {
    /// The echo shows other values than those sent.
    Mismatch {
        /// The echo line.
        echo: EchoKind,
        /// The values that differ.
        fields: Vec<FieldMismatch>,
    },
    /// The echo line is garbled.
    Corrupted {
        /// The echo line it claims to be.
        echo: EchoKind,
        /// How it is garbled.
        kind: GarbageKind,
        /// The line as received.
        line: String,
    },
    /// The firmware kept showing the calibration it showed before sending: it did not take the
    /// packet (CRC error on the wire, or firmware that does not read packets).
    Unchanged {
        /// The echo line that showed the previous calibration.
        echo: EchoKind,
        /// How long the echo was waited for (s).
        waited_s: f64,
    },
    /// No echo arrived in time.
    Missing {
        /// The echo lines still unconfirmed.
        missing: Vec<EchoKind>,
        /// How long the echo was waited for (s).
        waited_s: f64,
    },
}

impl fmt::Display for VerifyFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VerifyFailure::Mismatch { echo, fields } => {
                write!(f, "{} echo differs from what was sent:", echo.prefix())?;
                for m in fields {
                    write!(
                        f,
                        " {} sent {} echoed {} (tolerance {:.1e});",
                        m.field, m.sent, m.echoed, m.tolerance
                    )?;
                }
                Ok(())
            }
            VerifyFailure::Corrupted { echo, kind, line } => {
                write!(f, "{} echo is garbled ({kind}): {line:?}", echo.prefix())
            }
            VerifyFailure::Unchanged { echo, waited_s } => write!(
                f,
                "{} echo still shows the previous calibration after {waited_s:.2} s \
                 (packet not taken)",
                echo.prefix()
            ),
            VerifyFailure::Missing { missing, waited_s } => {
                let names: Vec<&str> = missing.iter().map(|k| k.prefix()).collect();
                write!(
                    f,
                    "no matching {} echo within {waited_s:.2} s",
                    names.join(" / ")
                )
            }
        }
    }
}

impl std::error::Error for VerifyFailure {}

/// Where a verification stands after a line.
#[derive(Clone, Debug, PartialEq)]
pub enum EchoProgress {
    /// Still waiting for a confirming echo.
    Pending,
    /// Both echoes matched what was sent.
    Confirmed,
    /// The verification failed.
    Failed(VerifyFailure),
}

/// Per-kind state of an [`EchoCheck`].
#[derive(Clone, Debug, Default)]
struct EchoState {
    confirmed: bool,
    /// Values of the echo taken as the calibration before the packet.
    reference: Option<Vec<f64>>,
    /// Whether `reference` was read before sending (else it is the first mismatching echo).
    reference_known: bool,
    /// Mismatching echoes equal to `reference`.
    stale: u32,
    /// The latest of them.
    last_stale: Option<VerifyFailure>,
    /// Garbled echoes.
    garbled: u32,
    /// The latest of them.
    last_garbled: Option<VerifyFailure>,
}

impl EchoState {
    /// What this kind fails on at a timeout, ranked (lower is reported first); `None` when
    /// nothing was seen.
    fn timeout_failure(&self, echo: EchoKind, waited_s: f64) -> Option<(u8, VerifyFailure)> {
        if self.confirmed {
            return None;
        }
        match (&self.last_stale, &self.last_garbled) {
            (Some(_), _) if self.reference_known => {
                Some((1, VerifyFailure::Unchanged { echo, waited_s }))
            }
            (Some(mismatch), _) => Some((0, mismatch.clone())),
            (None, Some(garbled)) => Some((2, garbled.clone())),
            (None, None) => None,
        }
    }
}

/// Compares the firmware's echoes with a sent packet.
#[derive(Clone, Debug)]
pub struct EchoCheck {
    cal1: [f64; CAL1_LEN],
    cal2: [f64; CAL2_LEN],
    states: [EchoState; 2],
}

fn values(echo: &Echo) -> Vec<f64> {
    echo.values().iter().map(|p| p.value).collect()
}

const KINDS: [EchoKind; 2] = [EchoKind::Cal1, EchoKind::Cal2];

impl EchoCheck {
    /// Expects the echo of `packet`. `previous` holds the echoes read before sending, if any
    /// (the last of each kind counts): the calibration the firmware showed then.
    pub fn new(packet: &CalibrationPacket, previous: &[Echo]) -> Self {
        let v = packet.values().map(f64::from);
        let s = packet.soft_iron().map(|row| row.map(f64::from));
        let mut states: [EchoState; 2] = Default::default();
        for echo in previous {
            let state = &mut states[echo.kind().index()];
            state.reference = Some(values(echo));
            state.reference_known = true;
        }
        EchoCheck {
            cal1: std::array::from_fn(|i| v[i]),
            cal2: std::array::from_fn(|i| s[i / 3][i % 3]),
            states,
        }
    }

    /// Echoes skipped so far: stale ones, and garbled ones let pass.
    pub fn echoes_skipped(&self) -> u32 {
        self.states.iter().map(|s| s.stale + s.garbled).sum()
    }

    fn progress(&self) -> EchoProgress {
        if self.states.iter().all(|s| s.confirmed) {
            EchoProgress::Confirmed
        } else {
            EchoProgress::Pending
        }
    }

    /// Takes a well-formed echo line.
    pub fn feed(&mut self, echo: &Echo) -> EchoProgress {
        let kind = echo.kind();
        let (expected, names): (&[f64], &[&'static str]) = match kind {
            EchoKind::Cal1 => (&self.cal1, &CAL1_FIELDS),
            EchoKind::Cal2 => (&self.cal2, &CAL2_FIELDS),
        };
        let fields: Vec<FieldMismatch> = echo
            .values()
            .iter()
            .zip(expected)
            .zip(names)
            .filter_map(|((printed, &sent), &field)| {
                let tolerance = 0.5 * printed.resolution + RELATIVE_SLACK * sent.abs().max(1.0);
                ((printed.value - sent).abs() > tolerance).then_some(FieldMismatch {
                    field,
                    sent,
                    echoed: printed.value,
                    tolerance,
                })
            })
            .collect();
        let state = &mut self.states[kind.index()];
        if state.confirmed {
            return self.progress();
        }
        if fields.is_empty() {
            state.confirmed = true;
            return self.progress();
        }
        let mismatch = VerifyFailure::Mismatch { echo: kind, fields };
        let echoed = values(echo);
        match &state.reference {
            Some(reference) if *reference != echoed => EchoProgress::Failed(mismatch),
            _ => {
                state.reference = Some(echoed);
                state.stale += 1;
                state.last_stale = Some(mismatch);
                EchoProgress::Pending
            }
        }
    }

    /// Takes a line that starts like echo `echo` but is garbled.
    pub fn feed_corrupted(
        &mut self,
        echo: EchoKind,
        kind: GarbageKind,
        line: &str,
    ) -> EchoProgress {
        let state = &mut self.states[echo.index()];
        if state.confirmed {
            return self.progress();
        }
        let failure = VerifyFailure::Corrupted {
            echo,
            kind,
            line: line.to_string(),
        };
        state.garbled += 1;
        if state.garbled > GARBLED_ECHOES_TOLERATED {
            return EchoProgress::Failed(failure);
        }
        state.last_garbled = Some(failure);
        EchoProgress::Pending
    }

    /// The failure to report when the wait ended after `waited_s` without confirmation (see
    /// the [module docs](self) for the order).
    pub fn timed_out(&self, waited_s: f64) -> VerifyFailure {
        let seen = KINDS
            .into_iter()
            .zip(&self.states)
            .filter_map(|(kind, state)| state.timeout_failure(kind, waited_s))
            .min_by_key(|(rank, _)| *rank);
        match seen {
            Some((_, failure)) => failure,
            None => VerifyFailure::Missing {
                missing: KINDS
                    .into_iter()
                    .zip(&self.states)
                    .filter(|(_, s)| !s.confirmed)
                    .map(|(kind, _)| kind)
                    .collect(),
                waited_s,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::motioncal::{MotionCalLine, parse_line};

    fn packet() -> CalibrationPacket {
        CalibrationPacket::magnetic(
            [-3.35, -0.74, -40.79],
            45.0,
            [
                [0.965, 0.018, 0.01],
                [0.018, 0.96, 0.003],
                [0.01, 0.003, 1.08],
            ],
        )
        .unwrap()
    }

    fn echo(line: &str) -> Echo {
        match parse_line(line) {
            Ok(MotionCalLine::Echo(e)) => e,
            other => panic!("{line:?} gave {other:?}"),
        }
    }

    const CAL1: &str = "Cal1:0.000,0.000,0.000,0.000,0.000,0.000,-3.350,-0.740,-40.790,45.000";
    const CAL2: &str = "Cal2:0.9650,0.0180,0.0100,0.0180,0.9600,0.0030,0.0100,0.0030,1.0800";
    const IDENTITY1: &str = "Cal1:0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,50.000";
    const IDENTITY2: &str = "Cal2:1.0000,0.0000,0.0000,0.0000,1.0000,0.0000,0.0000,0.0000,1.0000";

    #[test]
    fn both_echoes_confirm_in_either_order() {
        let mut c = EchoCheck::new(&packet(), &[]);
        assert_eq!(c.feed(&echo(CAL2)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(CAL1)), EchoProgress::Confirmed);
        assert_eq!(c.echoes_skipped(), 0);
    }

    #[test]
    fn rounding_to_the_printed_decimals_passes_one_digit_more_does_not() {
        let mut c = EchoCheck::new(&packet(), &[]);
        // 0.9650 printed with 2 decimals is 0.97 (or 0.96): both within half a unit.
        let coarse = "Cal2:0.97,0.02,0.01,0.02,0.96,0.00,0.01,0.00,1.08";
        assert_eq!(c.feed(&echo(coarse)), EchoProgress::Pending);
        let mut c = EchoCheck::new(&packet(), &[]);
        let off = "Cal2:0.9660,0.0180,0.0100,0.0180,0.9600,0.0030,0.0100,0.0030,1.0800";
        for _ in 0..3 {
            let progress = c.feed(&echo(off));
            assert_eq!(
                progress,
                EchoProgress::Pending,
                "may be the old calibration"
            );
        }
        let VerifyFailure::Mismatch { echo: kind, fields } = c.timed_out(1.0) else {
            panic!("the mismatch is reported at the timeout");
        };
        assert_eq!(kind, EchoKind::Cal2);
        assert_eq!(fields.len(), 1);
        assert_eq!(fields[0].field, "soft_iron[0][0]");
        assert_eq!(fields[0].echoed, 0.966);
        assert!((fields[0].sent - 0.965).abs() < 1e-7);
        assert!((fields[0].tolerance - 0.5e-4).abs() < 1e-5);
    }

    #[test]
    fn a_stale_echo_then_the_right_one_confirms() {
        let mut c = EchoCheck::new(&packet(), &[]);
        assert_eq!(c.feed(&echo(IDENTITY1)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(IDENTITY2)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(CAL1)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(CAL2)), EchoProgress::Confirmed);
        assert_eq!(c.echoes_skipped(), 2);
    }

    #[test]
    fn echoes_of_the_previous_calibration_are_stale_however_many() {
        let previous = [echo(IDENTITY1), echo(IDENTITY2)];
        let mut c = EchoCheck::new(&packet(), &previous);
        for _ in 0..5 {
            assert_eq!(c.feed(&echo(IDENTITY1)), EchoProgress::Pending);
            assert_eq!(c.feed(&echo(IDENTITY2)), EchoProgress::Pending);
        }
        assert_eq!(
            c.timed_out(3.0),
            VerifyFailure::Unchanged {
                echo: EchoKind::Cal1,
                waited_s: 3.0
            }
        );
        assert_eq!(c.feed(&echo(CAL1)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(CAL2)), EchoProgress::Confirmed);
        assert_eq!(c.echoes_skipped(), 10);
    }

    const OFF1: &str = "Cal1:0.000,0.000,0.000,0.000,0.000,0.000,-3.350,0.260,-40.790,45.000";

    fn fails_on_hard_iron_y(progress: EchoProgress) {
        let EchoProgress::Failed(VerifyFailure::Mismatch { fields, .. }) = progress else {
            panic!("expected a mismatch, got {progress:?}");
        };
        let names: Vec<_> = fields.iter().map(|m| m.field).collect();
        assert_eq!(names, ["hard_iron_ut[1]"]);
    }

    #[test]
    fn with_the_previous_echo_known_a_wrong_echo_fails_at_once() {
        let mut c = EchoCheck::new(&packet(), &[echo(IDENTITY1)]);
        fails_on_hard_iron_y(c.feed(&echo(OFF1)));
    }

    #[test]
    fn a_change_to_other_wrong_values_fails_at_once() {
        let mut c = EchoCheck::new(&packet(), &[]);
        assert_eq!(c.feed(&echo(IDENTITY1)), EchoProgress::Pending);
        assert_eq!(c.feed(&echo(IDENTITY1)), EchoProgress::Pending);
        fails_on_hard_iron_y(c.feed(&echo(OFF1)));
    }

    #[test]
    fn a_garbled_echo_twice_fails() {
        let mut c = EchoCheck::new(&packet(), &[]);
        let line = "Cal1:0.000,0.0#0";
        assert_eq!(
            c.feed_corrupted(EchoKind::Cal1, GarbageKind::FieldCount, line),
            EchoProgress::Pending
        );
        let EchoProgress::Failed(failure) =
            c.feed_corrupted(EchoKind::Cal1, GarbageKind::FieldCount, line)
        else {
            panic!("second garbled echo must fail");
        };
        assert!(
            failure.to_string().contains("Cal1: echo is garbled"),
            "{failure}"
        );
    }

    #[test]
    fn a_timeout_reports_the_last_bad_echo_or_what_is_missing() {
        let mut c = EchoCheck::new(&packet(), &[]);
        c.feed(&echo(CAL1));
        assert_eq!(
            c.timed_out(1.5),
            VerifyFailure::Missing {
                missing: vec![EchoKind::Cal2],
                waited_s: 1.5
            }
        );
        let mut c = EchoCheck::new(&packet(), &[]);
        c.feed(&echo(CAL2));
        c.feed(&echo(IDENTITY1));
        let failure = c.timed_out(1.5);
        let VerifyFailure::Mismatch { fields, .. } = &failure else {
            panic!("{failure:?}");
        };
        let names: Vec<_> = fields.iter().map(|m| m.field).collect();
        assert_eq!(
            names,
            [
                "hard_iron_ut[0]",
                "hard_iron_ut[1]",
                "hard_iron_ut[2]",
                "field_ut"
            ]
        );
        assert!(
            failure.to_string().contains("hard_iron_ut[1] sent"),
            "{failure}"
        );
        let mut c = EchoCheck::new(&packet(), &[]);
        c.feed(&echo(CAL1));
        c.feed_corrupted(EchoKind::Cal2, GarbageKind::BadNumber, "Cal2:x");
        assert!(matches!(c.timed_out(1.0), VerifyFailure::Corrupted { .. }));
        let failure = EchoCheck::new(&packet(), &[]).timed_out(2.0);
        assert_eq!(
            failure.to_string(),
            "no matching Cal1: / Cal2: echo within 2.00 s"
        );
    }
}
