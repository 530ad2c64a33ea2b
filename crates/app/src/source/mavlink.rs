//! The `mavlink:PATH[:BAUD][:ardupilot|px4]` device: a flight controller's compass, attitude, battery current and
//! IMU temperature over MAVLink, with the autopilot's own compass calibration undone, so the recording holds the
//! chip's raw field in µT as every other device's does.
//!
//! Opening it ([`MavlinkSource::start`]):
//!
//! 1. the autopilot's heartbeat is awaited (which autopilot, unless the device string names it; a port that speaks
//!    no MAVLink, or is silent, is said as such, naming the port);
//! 2. its compass calibration parameters are read: ArduPilot's `COMPASS_OFS_*`, `COMPASS_DIA_*`, `COMPASS_ODI_*`,
//!    `COMPASS_MOT_*`, `COMPASS_MOTCT` (and `COMPASS_SCALE` where the firmware has it), PX4's `CAL_MAG0_*` with
//!    `CAL_MAG_COMP_TYP` (and `CAL_MAG0_ROT`, `SENS_BOARD_ROT` where it has them); each is applied as the firmware
//!    applies it ([`magcal_flightlog::LoggedCalibration`], docs/autopilot.md) and undone sample by sample, with the
//!    battery current of the sample for the motor compensation;
//! 3. the streams are asked for at the rate given ([`magcal_autopilot::Connection::request_streams`]): the compass
//!    (`RAW_IMU`, `HIGHRES_IMU`), `ATTITUDE_QUATERNION`, `BATTERY_STATUS`;
//! 4. for [`PROBE`] the streams are watched: the compass must come; the attitude, the current and the temperature
//!    are recorded when they come; the rate each came at is measured and written to the recording's metadata
//!    (`sample_rate_hz` is the compass's); a battery current that comes less often than the compass is said
//!    (`current_rate`): a motor test's lag cannot be timed from it.
//!
//! Each compass sample waits for the first attitude after it, and takes the attitude interpolated to its own time
//! (the autopilot's time stamps), turned into the sensor's axes (sensor → NED, the recording's convention: the
//! body's FRD attitude for ArduPilot, whose compass field is in body axes; for PX4 the body attitude times the
//! sensor's rotation), and the battery current last received. The autopilot's clock restarting (a reboot) begins a
//! new segment of time, bridged by the host's clock. A compass silent for [`ASK_AGAIN`] (an autopilot that rebooted
//! forgets the rates it was asked for) is asked for again, with the other streams, once per silence. The frames the
//! link loses are counted from the gaps in the autopilot's sequence numbers ([`Source::link_loss`]; a reboot's
//! restart of them is undone when its clock is seen to go back) and noted in the recording when it ends.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use magcal_autopilot::streams::recording_messages;
use magcal_autopilot::{Autopilot, Connection, LinkError, Telemetry, telemetry};
use magcal_calib::diagnosis::MAX_CURRENT_UPDATE_INTERVALS;
use magcal_flightlog::LoggedCalibration;
use magcal_flightlog::recording::{matrix_to_quat, quat_mul};
use magcal_mockhw::SharedBench;
use mavlink::dialects::common::{MavMessage, MavResult};

use super::{Reading, Source, SourceError};

/// How long a flight controller has to send its heartbeat.
pub const HEARTBEAT_TIMEOUT: Duration = Duration::from_secs(5);
/// How long the streams are watched after asking for them, before recording starts.
pub const PROBE: Duration = Duration::from_millis(2000);
/// How long the compass may be silent before the streams are asked for again (at most half the idle timeout).
pub const ASK_AGAIN: Duration = Duration::from_secs(1);
/// How long a read waits before the recorder looks at Ctrl-C and the clock.
const POLL: Duration = Duration::from_millis(50);
/// A compass sample waits at most this long (autopilot time, s) for an attitude after it; then it is recorded
/// without one.
const ATTITUDE_WAIT_S: f64 = 1.0;
/// The name of the battery current's channel in the recording (as flight logs name it).
pub const CURRENT_CHANNEL: &str = "i_battery";

/// The calibration parameters read from `autopilot`: the ones every firmware has, then those only some have.
fn parameter_names(autopilot: Autopilot) -> (Vec<String>, Vec<String>) {
    let axes = |f: &dyn Fn(&str) -> String| ["X", "Y", "Z"].map(f).to_vec();
    match autopilot {
        Autopilot::ArduPilot => {
            let mut needed = Vec::new();
            for kind in ["OFS", "DIA", "ODI", "MOT"] {
                needed.extend(axes(&|a| format!("COMPASS_{kind}_{a}")));
            }
            needed.push("COMPASS_MOTCT".to_owned());
            (needed, vec!["COMPASS_SCALE".to_owned()])
        }
        Autopilot::Px4 => {
            let mut needed = vec!["CAL_MAG0_ID".to_owned()];
            for kind in ["OFF", "SCALE", "ODIAG", "COMP"] {
                needed.extend(axes(&|a| format!("CAL_MAG0_{a}{kind}")));
            }
            needed.push("CAL_MAG_COMP_TYP".to_owned());
            (
                needed,
                vec!["CAL_MAG0_ROT".to_owned(), "SENS_BOARD_ROT".to_owned()],
            )
        }
    }
}

/// A compass sample waiting for its attitude.
#[derive(Clone, Copy, Debug)]
struct Pending {
    /// Autopilot time, s.
    t_s: f64,
    /// The field as sent (calibrated, body axes), µT.
    sent_ut: [f64; 3],
    /// °C, NaN if not sent.
    temp_c: f64,
}

/// How many of each stream came, and the compass's first and last times, while probing.
#[derive(Clone, Copy, Debug, Default)]
struct Counts {
    compass: u64,
    attitude: u64,
    current: u64,
    temperature: u64,
    first_s: Option<f64>,
    last_s: f64,
}

/// A flight controller as a [`Source`]; see the [module docs](self).
pub struct MavlinkSource<P> {
    device: String,
    conn: Connection<P>,
    autopilot: Autopilot,
    calibration: LoggedCalibration,
    /// The sensor's axes into the body's, as a quaternion.
    sensor_to_body: [f64; 4],
    pending: VecDeque<Pending>,
    ready: VecDeque<Reading>,
    /// The last two attitudes (autopilot time, s; body → NED).
    attitudes: [Option<(f64, [f64; 4])>; 2],
    current_a: Option<f64>,
    has_attitude: bool,
    has_current: bool,
    has_temperature: bool,
    rate_hz: f64,
    /// The rate the streams were asked for, Hz.
    asked_hz: f64,
    /// Whether the streams were asked for again in this silence of the compass.
    asked_again: bool,
    metadata: Vec<(String, String)>,
    counts: Counts,
    /// Recording time = autopilot time + offset (changed at a restart of the autopilot's clock).
    offset_s: Option<f64>,
    last_autopilot_s: f64,
    last_t_s: f64,
    last_host: Instant,
    restarts: Vec<f64>,
    samples: u64,
    /// The time of the last reading handed out, s.
    delivered_t_s: f64,
    idle_timeout: Duration,
    last_compass_at: Instant,
    /// Whether the motor compensation is undone without the current (none came): said in the metadata.
    current_missing: bool,
}

impl<P: Read + Write> MavlinkSource<P> {
    /// Connects over `port` (named `path` in messages, `device` the device string), reads the calibration, asks for
    /// the streams at `rate_hz` and watches them for [`PROBE`]; see the [module docs](self).
    pub fn start(
        device: String,
        port: P,
        path: &str,
        assume: Option<Autopilot>,
        rate_hz: f64,
        idle_timeout: Duration,
    ) -> Result<MavlinkSource<P>, SourceError> {
        let open = |error: String| SourceError::Open {
            device: device.clone(),
            error,
        };
        let mut conn = Connection::new(port, path);
        let autopilot = conn
            .wait_heartbeat(HEARTBEAT_TIMEOUT, assume)
            .map_err(|e| open(e.to_string()))?;
        let (needed, optional) = parameter_names(autopilot);
        let mut params = std::collections::BTreeMap::new();
        for name in &needed {
            let p = conn.read_param(name).map_err(|e| {
                open(format!(
                    "reading the {autopilot} compass calibration to undo it: {e}"
                ))
            })?;
            params.insert(name.clone(), p.value);
        }
        for name in &optional {
            if let Some(p) = conn
                .read_param_if_any(name)
                .map_err(|e| open(e.to_string()))?
            {
                params.insert(name.clone(), p.value);
            }
        }
        let calibration = match autopilot {
            Autopilot::ArduPilot => LoggedCalibration::from_ardupilot(&params, 0),
            Autopilot::Px4 => LoggedCalibration::from_params(&params, 0),
        }
        .ok_or_else(|| {
            open(format!(
                "the {autopilot} compass 0 has no calibration slot (CAL_MAG0_ID 0: no magnetometer?)"
            ))
        })?;
        let messages = recording_messages(autopilot);
        let answers = conn
            .request_streams(&messages, rate_hz)
            .map_err(|e| open(e.to_string()))?;
        let asked: Vec<String> = answers
            .iter()
            .map(|a| {
                let said = match a.result {
                    Some(MavResult::MAV_RESULT_ACCEPTED) => "accepted".to_owned(),
                    Some(r) => format!("{r:?}"),
                    None => "no answer".to_owned(),
                };
                format!("{} {said}", a.name)
            })
            .collect();
        let mut source = MavlinkSource {
            device,
            conn,
            autopilot,
            sensor_to_body: matrix_to_quat(&calibration.rotation),
            calibration,
            pending: VecDeque::new(),
            ready: VecDeque::new(),
            attitudes: [None, None],
            current_a: None,
            has_attitude: true,
            has_current: true,
            has_temperature: true,
            rate_hz,
            asked_hz: rate_hz,
            asked_again: false,
            metadata: Vec::new(),
            counts: Counts::default(),
            offset_s: None,
            last_autopilot_s: f64::NEG_INFINITY,
            last_t_s: 0.0,
            last_host: Instant::now(),
            restarts: Vec::new(),
            samples: 0,
            delivered_t_s: 0.0,
            idle_timeout,
            last_compass_at: Instant::now(),
            current_missing: false,
        };
        let backlog: Vec<_> = source.conn.backlog.drain(..).collect();
        for (_, msg) in backlog {
            source.handle(&msg);
        }
        source.probe(&messages, rate_hz, &asked)?;
        Ok(source)
    }

    /// Watches the streams for [`PROBE`]: which came, at what rate; fills in the metadata.
    fn probe(
        &mut self,
        messages: &[(u32, &'static str); 3],
        asked_hz: f64,
        asked: &[String],
    ) -> Result<(), SourceError> {
        let deadline = Instant::now() + PROBE;
        self.counts = Counts::default();
        while let Some((_, msg)) =
            self.conn
                .next_message(deadline)
                .map_err(|e| SourceError::Open {
                    device: self.device.clone(),
                    error: e.to_string(),
                })?
        {
            self.handle(&msg);
        }
        let c = self.counts;
        let span_s = c.first_s.map_or(0.0, |f| c.last_s - f);
        if c.compass < 2 || span_s <= 0.0 {
            return Err(SourceError::Open {
                device: self.device.clone(),
                error: format!(
                    "the {} sent {} {} in {:.1} s after being asked for it at {} Hz ({}): is its compass enabled \
                     and healthy, and does this link carry its streams?",
                    self.autopilot,
                    c.compass,
                    messages[0].1,
                    PROBE.as_secs_f64(),
                    crate::cli::number(asked_hz),
                    asked.join(", ")
                ),
            });
        }
        let per_s = |n: u64| n.saturating_sub(1) as f64 / span_s;
        self.rate_hz = (per_s(c.compass) * 10.0).round() / 10.0;
        self.has_attitude = c.attitude > 0;
        self.has_current = c.current > 0;
        self.has_temperature = c.temperature > 0;
        let got = |n: u64, name: &str| {
            if n == 0 {
                format!("{name} none")
            } else {
                format!("{name} {:.1} Hz", per_s(n).max(0.0))
            }
        };
        self.metadata.push((
            "mavlink_streams".to_owned(),
            format!(
                "asked {} Hz ({}); got {}, {}, {}",
                crate::cli::number(asked_hz),
                asked.join(", "),
                got(c.compass, messages[0].1),
                got(c.attitude, messages[1].1),
                got(c.current, messages[2].1),
            ),
        ));
        if self.has_current && per_s(c.current) * MAX_CURRENT_UPDATE_INTERVALS < per_s(c.compass) {
            self.metadata.push((
                "current_rate".to_owned(),
                format!(
                    "{} came at {:.1} Hz, less often than the compass: a bench motor test's lag of the field behind \
                     the current will not be determined (magcal-fit says so; the coefficients are still fitted)",
                    messages[2].1,
                    per_s(c.current)
                ),
            ));
        }
        let cal = &self.calibration;
        let needs_current = matches!(cal.comp_type, 2 | 3) && cal.comp != [0.0; 3];
        self.current_missing = needs_current && !self.has_current;
        self.metadata.push((
            "autopilot_calibration_undone".to_owned(),
            format!(
                "{} {} ({}); the field recorded is the chip's own, µT{}",
                self.autopilot,
                cal.describe(),
                match self.autopilot {
                    Autopilot::ArduPilot => "RAW_IMU = M·(raw + OFS) + MOT·I undone",
                    Autopilot::Px4 => "HIGHRES_IMU = R·S·(raw + I·COMP − OFF) undone",
                },
                if self.current_missing {
                    "; no battery current came, so the motor compensation was undone as at 0 A"
                } else if cal.comp_type == 1 && cal.comp != [0.0; 3] {
                    "; the throttle-based motor compensation (type 1) was not undone"
                } else {
                    ""
                }
            ),
        ));
        if !self.has_attitude {
            // Nothing will come to release them.
            let pending: Vec<_> = self.pending.drain(..).collect();
            for p in pending {
                self.release(p, None);
            }
        }
        Ok(())
    }

    /// Recording time of autopilot time `t_s`: a clock that went back began a new segment, bridged by the host.
    fn time_of(&mut self, t_s: f64) -> f64 {
        let now = Instant::now();
        let offset = match self.offset_s {
            None => -t_s,
            Some(_) if t_s < self.last_autopilot_s => {
                let bridged = self.last_t_s + now.duration_since(self.last_host).as_secs_f64();
                self.restarts.push(bridged);
                self.conn.numbering_restarted();
                bridged - t_s
            }
            Some(o) => o,
        };
        self.offset_s = Some(offset);
        self.last_autopilot_s = t_s;
        self.last_host = now;
        (t_s + offset).max(self.last_t_s)
    }

    /// The raw field behind a field sent, µT, sensor axes.
    fn undo(&self, sent_ut: [f64; 3], current_a: Option<f64>) -> [f64; 3] {
        let power = self.calibration.power(current_a.unwrap_or(0.0));
        let sent_g = sent_ut.map(|v| v / 100.0);
        self.calibration
            .undo(sent_g, power)
            .map_or(sent_ut, |g| g.map(|v| v * 100.0))
    }

    /// Turns a pending sample into a reading, with attitude `body_q` (body → NED) if any.
    fn release(&mut self, p: Pending, body_q: Option<[f64; 4]>) {
        let t_s = self.time_of(p.t_s);
        self.last_t_s = t_s;
        let current_a = if self.has_current {
            self.current_a
        } else {
            None
        };
        self.ready.push_back(Reading {
            t_s,
            mag_ut: self.undo(p.sent_ut, current_a),
            temp_c: p.temp_c.is_finite().then_some(p.temp_c),
            quat: body_q.map(|q| quat_mul(q, self.sensor_to_body)),
            current_a,
        });
    }

    /// The attitude at `t_s` from the last two (normalised linear interpolation, the shorter way).
    fn attitude_at(&self, t_s: f64) -> Option<[f64; 4]> {
        let (t1, q1) = self.attitudes[1]?;
        let Some((t0, q0)) = self.attitudes[0] else {
            return Some(q1);
        };
        if t1 <= t0 || t_s >= t1 {
            return Some(q1);
        }
        let f = ((t_s - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let sign = if (0..4).map(|k| q0[k] * q1[k]).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let q: [f64; 4] = std::array::from_fn(|k| (1.0 - f) * q0[k] + f * sign * q1[k]);
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        Some(q.map(|v| v / n))
    }

    /// The link failing while recording.
    fn link_failed(&self, e: LinkError) -> SourceError {
        let reason = match e {
            LinkError::Disconnected { reason, .. } => reason,
            e => e.to_string(),
        };
        SourceError::Disconnected {
            device: self.device.clone(),
            samples: self.samples,
            reason,
        }
    }

    /// Takes one message.
    fn handle(&mut self, msg: &MavMessage) {
        let Some(t) = telemetry(msg) else {
            return;
        };
        match t {
            Telemetry::Mag {
                instance: 0,
                field_ut,
                temp_c,
                t_s,
            } => {
                if t_s < self.counts.last_s {
                    // The clock went back while probing (a reboot): the rates are measured from then on.
                    self.counts = Counts::default();
                }
                self.asked_again = false;
                self.counts.compass += 1;
                self.counts.first_s.get_or_insert(t_s);
                self.counts.last_s = t_s;
                self.counts.temperature += u64::from(temp_c.is_finite());
                self.last_compass_at = Instant::now();
                let p = Pending {
                    t_s,
                    sent_ut: field_ut,
                    temp_c,
                };
                if self.has_attitude {
                    self.pending.push_back(p);
                    // An attitude stream that stopped: do not hold the samples for ever.
                    while let Some(first) = self.pending.front().copied() {
                        if t_s - first.t_s <= ATTITUDE_WAIT_S && t_s >= first.t_s {
                            break;
                        }
                        self.pending.pop_front();
                        self.release(first, None);
                    }
                } else {
                    self.release(p, None);
                }
            }
            Telemetry::Mag { .. } | Telemetry::Param { .. } => {}
            Telemetry::Attitude { q, t_s } => {
                self.counts.attitude += 1;
                self.attitudes = [self.attitudes[1], Some((t_s, q))];
                // Samples up to a millisecond before it may be its own (the attitude's time is in whole ms): they
                // wait for the next one, to be interpolated.
                while let Some(first) = self.pending.front().copied() {
                    if first.t_s > t_s - 0.0015 && first.t_s <= t_s + ATTITUDE_WAIT_S {
                        break;
                    }
                    self.pending.pop_front();
                    let q = if first.t_s > t_s {
                        None
                    } else {
                        self.attitude_at(first.t_s)
                    };
                    self.release(first, q);
                }
            }
            Telemetry::Current { current_a } => {
                self.counts.current += 1;
                self.current_a = Some(current_a);
            }
        }
    }
}

impl<P: Read + Write> Source for MavlinkSource<P> {
    fn device(&self) -> &str {
        &self.device
    }

    fn sensor(&self) -> String {
        let message = recording_messages(self.autopilot)[0].1;
        format!("{} compass 0 ({message})", self.autopilot)
    }

    fn rate_hz(&self) -> Option<f64> {
        Some(self.rate_hz)
    }

    fn has_temperature(&self) -> bool {
        self.has_temperature
    }

    fn has_quaternion(&self) -> bool {
        self.has_attitude
    }

    fn current_channel(&self) -> Option<String> {
        self.has_current.then(|| CURRENT_CHANNEL.to_owned())
    }

    fn metadata(&self) -> Vec<(String, String)> {
        self.metadata.clone()
    }

    /// The next sample, or `None` after [`POLL`]; no compass sample for the idle timeout is an error, and so is a
    /// disconnect.
    fn next_reading(&mut self) -> Result<Option<Reading>, SourceError> {
        let deadline = Instant::now() + POLL;
        loop {
            if let Some(r) = self.ready.pop_front() {
                self.samples += 1;
                self.delivered_t_s = r.t_s;
                return Ok(Some(r));
            }
            match self.conn.next_message(deadline) {
                Ok(Some((_, msg))) => self.handle(&msg),
                Ok(None) => break,
                Err(e) => return Err(self.link_failed(e)),
            }
        }
        let waited = self.last_compass_at.elapsed();
        if !self.asked_again && waited >= ASK_AGAIN.min(self.idle_timeout / 2) {
            self.asked_again = true;
            let messages = recording_messages(self.autopilot);
            if let Err(e) = self.conn.request_streams(&messages, self.asked_hz) {
                return Err(self.link_failed(e));
            }
            let backlog: Vec<_> = self.conn.backlog.drain(..).collect();
            for (_, msg) in backlog {
                self.handle(&msg);
            }
            return Ok(None);
        }
        if waited >= self.idle_timeout {
            let message = recording_messages(self.autopilot)[0].1;
            return Err(SourceError::NoSamples {
                device: self.device.clone(),
                samples: self.samples,
                waited_s: waited.as_secs_f64(),
                cause: format!(
                    "the {} stopped sending {message}, and sent none when asked for it again (rebooted and \
                     disarmed its streams, or the link dropped?)",
                    self.autopilot
                ),
            });
        }
        Ok(None)
    }

    /// The time of the last reading handed out (those taken while probing wait in order).
    fn now_s(&self) -> f64 {
        self.delivered_t_s
    }

    fn saturated(&self) -> u64 {
        0
    }

    fn garbage(&self) -> Option<magcal_driver::serial::GarbageCounts> {
        None
    }

    fn bench(&self) -> Option<&SharedBench> {
        None
    }

    fn clock_may_restart(&self) -> bool {
        true
    }

    fn clock_restarts(&self) -> &[f64] {
        &self.restarts
    }

    fn link_loss(&self) -> Option<magcal_autopilot::LinkLoss> {
        Some(self.conn.link_loss())
    }
}
