//! The MotionCal calibration packet: 68 bytes that firmware stores as its calibration.
//!
//! Layout, as MotionCal's `send_calibration()` (`rawdata.c`) writes it and Adafruit's
//! calibration sketches' `receiveCalibration()` read it:
//!
//! | bytes | content |
//! |---|---|
//! | 0–1 | signature 117, 84 |
//! | 2–13 | accelerometer zero-g offsets x, y, z (f32) |
//! | 14–25 | gyro zero-rate offsets x, y, z (f32) |
//! | 26–37 | hard-iron offset V x, y, z (f32, µT) |
//! | 38–41 | geomagnetic field magnitude (f32, µT) |
//! | 42–53 | soft-iron diagonal S₀₀, S₁₁, S₂₂ (f32) |
//! | 54–65 | soft-iron off-diagonal S₀₁, S₀₂, S₁₂ (f32) |
//! | 66–67 | CRC-16, low byte first |
//!
//! Every f32 is little-endian. The CRC is CRC-16/MODBUS: reflected polynomial 0xA001, initial
//! value 0xFFFF, over bytes 0–65; appended low byte first, so the CRC of all 68 bytes is 0, which
//! is the firmware's acceptance test. The firmware applies `calibrated = S · (raw − V)` with S
//! symmetric (it fills `mag_softiron[1]` and `[3]` from S₀₁, and so on). MotionCal itself sends
//! zero accelerometer and gyro offsets; Adafruit's library holds them in m/s² and rad/s.
//! See [`affine`](super::affine) for getting V and S from magcal's `B = A·m + b`.

use std::fmt;

/// Length of a calibration packet, in bytes.
pub const PACKET_LEN: usize = 68;
/// The two bytes a packet starts with.
pub const SIGNATURE: [u8; 2] = [117, 84];
/// Largest relative asymmetry `|S_ij − S_ji| / max|S|` that [`CalibrationPacket::magnetic`]
/// accepts as rounding; the packet carries only one of the two.
pub const SYMMETRY_TOLERANCE: f64 = 1e-9;

const FLOATS: usize = 16;

/// CRC-16/MODBUS (reflected polynomial 0xA001, initial value 0xFFFF, no final xor).
pub fn crc16(bytes: &[u8]) -> u16 {
    bytes.iter().fold(0xFFFF, |crc, &byte| {
        (0..8).fold(crc ^ u16::from(byte), |crc, _| {
            if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            }
        })
    })
}

/// What a MotionCal packet carries, in the packet's own f32 precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationPacket {
    /// Accelerometer zero-g offsets (m/s² in Adafruit's library; MotionCal sends zeros).
    pub accel_zero_g_m_s2: [f32; 3],
    /// Gyro zero-rate offsets (rad/s in Adafruit's library; MotionCal sends zeros).
    pub gyro_zero_rate_rad_s: [f32; 3],
    /// Hard-iron offset V (µT), subtracted from the raw field.
    pub hard_iron_ut: [f32; 3],
    /// Magnitude of the geomagnetic field the calibration maps onto (µT).
    pub field_ut: f32,
    /// Soft-iron diagonal `[S₀₀, S₁₁, S₂₂]`.
    pub soft_iron_diag: [f32; 3],
    /// Soft-iron off-diagonal `[S₀₁, S₀₂, S₁₂]` (S is symmetric).
    pub soft_iron_offdiag: [f32; 3],
}

/// Why [`CalibrationPacket::magnetic`] refused its arguments.
#[derive(Clone, Debug, PartialEq)]
pub enum PacketError {
    /// A value is NaN or infinite, or does not fit an f32.
    NotFinite {
        /// Which argument.
        field: &'static str,
    },
    /// S is not symmetric; only a symmetric S can be sent (see [`affine`](super::affine)).
    NotSymmetric {
        /// Largest `|S_ij − S_ji|`.
        max_difference: f64,
    },
    /// S is not positive definite, so it is no soft-iron correction (a reflection, or a
    /// degenerate fit).
    NotPositiveDefinite,
}

impl fmt::Display for PacketError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PacketError::NotFinite { field } => write!(f, "{field} is not a finite f32"),
            PacketError::NotSymmetric { max_difference } => write!(
                f,
                "soft-iron matrix is not symmetric (|S_ij - S_ji| up to {max_difference:.3e}); \
                 MotionCal firmware holds a symmetric matrix only"
            ),
            PacketError::NotPositiveDefinite => {
                f.write_str("soft-iron matrix is not positive definite")
            }
        }
    }
}

impl std::error::Error for PacketError {}

/// Why [`decode`] refused 68 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The first two bytes are not 117, 84.
    Signature([u8; 2]),
    /// The CRC does not match.
    Crc {
        /// CRC of bytes 0–65.
        computed: u16,
        /// CRC carried in bytes 66–67.
        carried: u16,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DecodeError::Signature(s) => write!(f, "bad signature {}, {}", s[0], s[1]),
            DecodeError::Crc { computed, carried } => {
                write!(
                    f,
                    "CRC mismatch: computed {computed:#06x}, carried {carried:#06x}"
                )
            }
        }
    }
}

impl std::error::Error for DecodeError {}

fn to_f32(value: f64, field: &'static str) -> Result<f32, PacketError> {
    let narrowed = value as f32; // out of range becomes infinite, caught here

    if narrowed.is_finite() {
        Ok(narrowed)
    } else {
        Err(PacketError::NotFinite { field })
    }
}

impl CalibrationPacket {
    /// A magnetic calibration with zero accelerometer and gyro offsets, as MotionCal sends it:
    /// hard-iron offset V (µT), field magnitude (µT) and symmetric positive-definite soft-iron
    /// matrix S, for `calibrated = S · (raw − V)`.
    pub fn magnetic(
        hard_iron_ut: [f64; 3],
        field_ut: f64,
        soft_iron: [[f64; 3]; 3],
    ) -> Result<Self, PacketError> {
        let scale = soft_iron.iter().flatten().fold(0f64, |m, v| m.max(v.abs()));
        let max_difference = [(0, 1), (0, 2), (1, 2)]
            .iter()
            .map(|&(i, j)| (soft_iron[i][j] - soft_iron[j][i]).abs())
            .fold(0f64, f64::max);
        if max_difference > SYMMETRY_TOLERANCE * scale {
            return Err(PacketError::NotSymmetric { max_difference });
        }
        let s = soft_iron;
        let minor2 = s[0][0] * s[1][1] - s[0][1] * s[1][0];
        let det = s[0][0] * (s[1][1] * s[2][2] - s[1][2] * s[2][1])
            - s[0][1] * (s[1][0] * s[2][2] - s[1][2] * s[2][0])
            + s[0][2] * (s[1][0] * s[2][1] - s[1][1] * s[2][0]);
        let mut hard = [0f32; 3];
        for (out, v) in hard.iter_mut().zip(hard_iron_ut) {
            *out = to_f32(v, "hard_iron_ut")?;
        }
        let mut diag = [0f32; 3];
        let mut offdiag = [0f32; 3];
        for k in 0..3 {
            diag[k] = to_f32(s[k][k], "soft_iron")?;
        }
        for (k, (i, j)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
            offdiag[k] = to_f32(s[i][j], "soft_iron")?;
        }
        if !(s[0][0] > 0.0 && minor2 > 0.0 && det > 0.0) {
            return Err(PacketError::NotPositiveDefinite);
        }
        Ok(CalibrationPacket {
            accel_zero_g_m_s2: [0.0; 3],
            gyro_zero_rate_rad_s: [0.0; 3],
            hard_iron_ut: hard,
            field_ut: to_f32(field_ut, "field_ut")?,
            soft_iron_diag: diag,
            soft_iron_offdiag: offdiag,
        })
    }

    /// The full symmetric soft-iron matrix S.
    pub fn soft_iron(&self) -> [[f32; 3]; 3] {
        let [xx, yy, zz] = self.soft_iron_diag;
        let [xy, xz, yz] = self.soft_iron_offdiag;
        [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    }

    /// The 16 floats in packet order.
    pub fn values(&self) -> [f32; FLOATS] {
        let mut v = [0f32; FLOATS];
        v[0..3].copy_from_slice(&self.accel_zero_g_m_s2);
        v[3..6].copy_from_slice(&self.gyro_zero_rate_rad_s);
        v[6..9].copy_from_slice(&self.hard_iron_ut);
        v[9] = self.field_ut;
        v[10..13].copy_from_slice(&self.soft_iron_diag);
        v[13..16].copy_from_slice(&self.soft_iron_offdiag);
        v
    }

    /// The packet holding the 16 floats `v`, in packet order.
    pub fn from_values(v: [f32; FLOATS]) -> Self {
        CalibrationPacket {
            accel_zero_g_m_s2: [v[0], v[1], v[2]],
            gyro_zero_rate_rad_s: [v[3], v[4], v[5]],
            hard_iron_ut: [v[6], v[7], v[8]],
            field_ut: v[9],
            soft_iron_diag: [v[10], v[11], v[12]],
            soft_iron_offdiag: [v[13], v[14], v[15]],
        }
    }
}

/// The 68 bytes of `packet`.
pub fn encode(packet: &CalibrationPacket) -> [u8; PACKET_LEN] {
    let mut bytes = [0u8; PACKET_LEN];
    bytes[..2].copy_from_slice(&SIGNATURE);
    for (chunk, value) in bytes[2..PACKET_LEN - 2]
        .chunks_exact_mut(4)
        .zip(packet.values())
    {
        chunk.copy_from_slice(&value.to_le_bytes());
    }
    let crc = crc16(&bytes[..PACKET_LEN - 2]);
    bytes[PACKET_LEN - 2..].copy_from_slice(&crc.to_le_bytes());
    bytes
}

/// The packet in `bytes`, if its signature and CRC hold (what firmware checks before storing).
pub fn decode(bytes: &[u8; PACKET_LEN]) -> Result<CalibrationPacket, DecodeError> {
    if bytes[..2] != SIGNATURE {
        return Err(DecodeError::Signature([bytes[0], bytes[1]]));
    }
    let computed = crc16(&bytes[..PACKET_LEN - 2]);
    let carried = u16::from_le_bytes([bytes[PACKET_LEN - 2], bytes[PACKET_LEN - 1]]);
    if computed != carried {
        return Err(DecodeError::Crc { computed, carried });
    }
    let mut v = [0f32; FLOATS];
    for (value, chunk) in v.iter_mut().zip(bytes[2..PACKET_LEN - 2].chunks_exact(4)) {
        *value = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
    }
    Ok(CalibrationPacket::from_values(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> CalibrationPacket {
        // The values of Adafruit's sensor_calibration_write example.
        CalibrationPacket::magnetic(
            [-3.35, -0.74, -40.79],
            45.0,
            [
                [0.965, 0.018, 0.010],
                [0.018, 0.960, 0.003],
                [0.010, 0.003, 1.080],
            ],
        )
        .unwrap()
    }

    #[test]
    fn crc16_is_crc16_modbus() {
        // The catalogued check value of CRC-16/MODBUS.
        assert_eq!(crc16(b"123456789"), 0x4B37);
        assert_eq!(crc16(&[]), 0xFFFF);
    }

    #[test]
    fn layout_signature_and_crc() {
        let bytes = encode(&example());
        assert_eq!(bytes[..2], [117, 84]);
        assert_eq!(bytes[2..26], [0; 24], "accel and gyro offsets are zero");
        assert_eq!(bytes[26..30], (-3.35f32).to_le_bytes());
        assert_eq!(bytes[38..42], 45f32.to_le_bytes());
        assert_eq!(bytes[42..46], 0.965f32.to_le_bytes(), "S00 first");
        assert_eq!(bytes[46..50], 0.960f32.to_le_bytes(), "then S11");
        assert_eq!(bytes[50..54], 1.080f32.to_le_bytes(), "then S22");
        assert_eq!(bytes[54..58], 0.018f32.to_le_bytes(), "then S01");
        assert_eq!(bytes[58..62], 0.010f32.to_le_bytes(), "then S02");
        assert_eq!(bytes[62..66], 0.003f32.to_le_bytes(), "then S12");
        assert_eq!(crc16(&bytes), 0, "the firmware's acceptance test");
    }

    #[test]
    fn decode_inverts_encode_and_checks() {
        let p = example();
        let bytes = encode(&p);
        assert_eq!(decode(&bytes), Ok(p));
        assert_eq!(p.soft_iron()[2][1], 0.003);
        let mut flipped = bytes;
        flipped[30] ^= 0x01;
        assert!(matches!(decode(&flipped), Err(DecodeError::Crc { .. })));
        let mut unsigned = bytes;
        unsigned[1] = 0;
        assert_eq!(decode(&unsigned), Err(DecodeError::Signature([117, 0])));
    }

    #[test]
    fn refuses_what_firmware_cannot_hold() {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(CalibrationPacket::magnetic([0.0; 3], 50.0, id).is_ok());
        let mut skew = id;
        skew[0][1] = 0.1;
        assert!(matches!(
            CalibrationPacket::magnetic([0.0; 3], 50.0, skew),
            Err(PacketError::NotSymmetric { .. })
        ));
        let mut flip = id;
        flip[2][2] = -1.0;
        assert_eq!(
            CalibrationPacket::magnetic([0.0; 3], 50.0, flip),
            Err(PacketError::NotPositiveDefinite)
        );
        assert_eq!(
            CalibrationPacket::magnetic([f64::NAN, 0.0, 0.0], 50.0, id),
            Err(PacketError::NotFinite {
                field: "hard_iron_ut"
            })
        );
        assert_eq!(
            CalibrationPacket::magnetic([0.0; 3], 1e40, id),
            Err(PacketError::NotFinite { field: "field_ut" })
        );
    }
}
