//! Asking an autopilot for the telemetry a recording needs, at a rate: `SET_MESSAGE_INTERVAL` (`COMMAND_LONG`,
//! MAVLink's way since 2015, ArduPilot and PX4 both take it, each answering `COMMAND_ACK`) for each message, and for
//! ArduPilot also `REQUEST_DATA_STREAM` of the stream groups that hold them (older firmware, and ground stations'
//! habit). What rate the autopilot then sends is for the receiver to measure: an autopilot may accept and send
//! slower (a busy link, a cap of its own).

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use mavlink::MessageData;
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, BATTERY_STATUS_DATA, COMMAND_LONG_DATA, HIGHRES_IMU_DATA, MavCmd,
    MavMessage, MavResult, RAW_IMU_DATA,
};
#[allow(deprecated)]
// superseded by SET_MESSAGE_INTERVAL, still what ArduPilot's stream groups answer
use mavlink::dialects::common::{MavDataStream, REQUEST_DATA_STREAM_DATA};

use crate::link::{Autopilot, Connection, LinkError};

/// How long the answers to the requests are waited for.
pub const ACK_TIMEOUT: Duration = Duration::from_millis(1500);

/// The messages a calibration recording reads from `autopilot`, by id and name: its compass (`RAW_IMU`,
/// `HIGHRES_IMU`), `ATTITUDE_QUATERNION`, `BATTERY_STATUS`.
pub fn recording_messages(autopilot: Autopilot) -> [(u32, &'static str); 3] {
    let compass = match autopilot {
        Autopilot::ArduPilot => (RAW_IMU_DATA::ID, RAW_IMU_DATA::NAME),
        Autopilot::Px4 => (HIGHRES_IMU_DATA::ID, HIGHRES_IMU_DATA::NAME),
    };
    [
        compass,
        (ATTITUDE_QUATERNION_DATA::ID, ATTITUDE_QUATERNION_DATA::NAME),
        (BATTERY_STATUS_DATA::ID, BATTERY_STATUS_DATA::NAME),
    ]
}

/// What the autopilot answered to one message's `SET_MESSAGE_INTERVAL`.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamAnswer {
    /// The message.
    pub name: &'static str,
    /// Its `COMMAND_ACK` result, if one came (acks carry no message id: they are matched in order).
    pub result: Option<MavResult>,
}

impl<P: Read + Write> Connection<P> {
    /// Asks for each of `messages` (id, name) at `rate_hz`: `SET_MESSAGE_INTERVAL` each, and for ArduPilot
    /// `REQUEST_DATA_STREAM` of `RAW_SENSORS` and `EXTENDED_STATUS` at the same rate. Waits up to [`ACK_TIMEOUT`]
    /// for the `COMMAND_ACK`s; other messages go to the [`backlog`](Self::backlog).
    #[allow(deprecated)]
    pub fn request_streams(
        &mut self,
        messages: &[(u32, &'static str)],
        rate_hz: f64,
    ) -> Result<Vec<StreamAnswer>, LinkError> {
        let (target_system, target_component) = self.target().unwrap_or((1, 1));
        if self.autopilot() == Some(Autopilot::ArduPilot) {
            for stream in [
                MavDataStream::MAV_DATA_STREAM_RAW_SENSORS,
                MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS,
            ] {
                self.send(&MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
                    req_message_rate: rate_hz.round().clamp(1.0, f64::from(u16::MAX)) as u16,
                    target_system,
                    target_component,
                    req_stream_id: stream,
                    start_stop: 1,
                }))?;
            }
        }
        for (id, _) in messages {
            self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: *id as f32,
                param2: (1e6 / rate_hz) as f32,
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                target_system,
                target_component,
                ..COMMAND_LONG_DATA::default()
            }))?;
        }
        let mut answers: Vec<StreamAnswer> = messages
            .iter()
            .map(|(_, name)| StreamAnswer { name, result: None })
            .collect();
        let mut got = 0;
        let deadline = Instant::now() + ACK_TIMEOUT;
        while got < answers.len() {
            let Some((header, msg)) = self.next_message(deadline)? else {
                break;
            };
            match &msg {
                MavMessage::COMMAND_ACK(ack)
                    if ack.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
                {
                    answers[got].result = Some(ack.result);
                    got += 1;
                }
                _ => self.keep((header, msg)),
            }
        }
        Ok(answers)
    }
}
