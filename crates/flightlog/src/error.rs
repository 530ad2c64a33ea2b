//! Why a flight log could not be made into a recording: each names the file, what is wrong and what to do.

/// Why a flight log could not be read or made into a recording.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be opened or read.
    #[error("{file}: cannot be read: {source}")]
    Io {
        /// The file.
        file: String,
        /// The error.
        source: std::io::Error,
    },
    /// Not a ULog file, or its header or message definitions are broken.
    #[error(
        "{file}: not a readable PX4 ULog file ({detail}): its header or message definitions are corrupt or it is \
         another format; download the log again from the vehicle (the .ulg from the SD card or QGroundControl)"
    )]
    Corrupt {
        /// The file.
        file: String,
        /// What the parser said.
        detail: String,
    },
    /// No magnetometer topic was logged.
    #[error(
        "{file}: no magnetometer in the log (neither sensor_mag nor vehicle_magnetometer was logged): enable the \
         sensor topics in the logging profile (SDLOG_PROFILE, e.g. the default plus 'sensor comparison') and fly again"
    )]
    NoMagnetometer {
        /// The file.
        file: String,
    },
    /// No attitude was logged.
    #[error(
        "{file}: no attitude in the log (vehicle_attitude was not logged, or holds no valid quaternion): without it \
         the field cannot be compared with the World Magnetic Model; log with the default SDLOG_PROFILE and fly again"
    )]
    NoAttitude {
        /// The file.
        file: String,
    },
    /// The instance asked for is not in the log.
    #[error(
        "{file}: there is no magnetometer {asked}: the log holds {available}; pick one of those with --mag"
    )]
    NoSuchInstance {
        /// The file.
        file: String,
        /// What was asked.
        asked: String,
        /// What there is, in words.
        available: String,
    },
    /// The magnetometer's samples fall outside the attitude's time span.
    #[error(
        "{file}: the magnetometer's {mag} samples and the attitude's do not overlap in time: no row has both"
    )]
    NoOverlap {
        /// The file.
        file: String,
        /// Which magnetometer.
        mag: String,
    },
    /// A magnetometer whose logged calibration cannot be undone.
    #[error("{file}: {mag}: {why}")]
    Calibration {
        /// The file.
        file: String,
        /// Which magnetometer.
        mag: String,
        /// What is wrong.
        why: String,
    },
}
