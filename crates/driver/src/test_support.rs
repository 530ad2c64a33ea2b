//! Helpers shared by the chips' mock-bus tests.

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};

/// The error a mock bus returns for a NACK.
pub(crate) const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

/// Asserts two vectors agree to within `tolerance` per axis.
#[track_caller]
pub(crate) fn assert_close(actual: [f32; 3], expected: [f32; 3], tolerance: f32) {
    for axis in 0..3 {
        assert!(
            (actual[axis] - expected[axis]).abs() <= tolerance,
            "axis {axis}: got {actual:?}, expected {expected:?} (± {tolerance})"
        );
    }
}
