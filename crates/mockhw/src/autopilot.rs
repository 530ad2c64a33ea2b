//! A simulated autopilot: ArduPilot or PX4 as a ground station sees it over MAVLink 2, on any byte port (a
//! pseudo-terminal's master for the tools, a [`magcal_autopilot::MemoryPort`] in unit tests).
//!
//! Its compass is the simulator's [`Bench`]: a sensor with hard and soft iron ([`BenchConfig::sensor`]) and any
//! effects — a motor-current bias on channel 0 (the battery current, which follows a [`CurrentProfile`]: slow ramps
//! of the throttle, then [`Blips`] when asked; the field following it [`TwinConfig::current_lag_s`] late), a time
//! lag — computed by the same function the fitter's regressors use. The hand turns it, or holds it still for a bench
//! motor test ([`TwinConfig::held`]). Like the real firmware it applies its own
//! calibration to what it sends, with its parameters as they are at that moment:
//!
//! - ArduPilot: `RAW_IMU` (compass in mGauss) = `M·(raw + COMPASS_OFS) + COMPASS_MOT·I` (the last with
//!   `COMPASS_MOTCT` = 2), `M` from `COMPASS_DIA_*` and `COMPASS_ODI_*`;
//! - PX4: `HIGHRES_IMU` (gauss) = `S·(raw + I/1000·CAL_MAG0_*COMP − CAL_MAG0_*OFF)` (the current term with
//!   `CAL_MAG_COMP_TYP` = 2), `S` from `CAL_MAG0_*SCALE` and `*ODIAG`;
//!
//! and `ATTITUDE_QUATERNION` (the bench's attitude), `BATTERY_STATUS` (the current, cA) and a `HEARTBEAT` each
//! second, all in bench time paced against the wall clock.
//!
//! Its streams start at [`TwinConfig::rate_hz`], or, with [`TwinConfig::await_request`], only when a ground station
//! asks: `SET_MESSAGE_INTERVAL` (`COMMAND_LONG`, answered by `COMMAND_ACK`) for any of the three messages, and for
//! ArduPilot also `REQUEST_DATA_STREAM` (`RAW_SENSORS`: `RAW_IMU`; `EXTENDED_STATUS`: `BATTERY_STATUS`; as
//! ArduPilot, `ATTITUDE_QUATERNION` is in no stream group). A rate above [`TwinConfig::rate_hz`] gets that rate.
//!
//! Its parameters answer `PARAM_REQUEST_READ` (by name or index) and `PARAM_REQUEST_LIST` with `PARAM_VALUE`, and
//! `PARAM_SET` with `PARAM_VALUE` holding the new value — or, for a value outside the parameter's range (or not a
//! number), its old value, which is how a ground station sees a refusal. A name it does not have gets no answer,
//! as ArduPilot and PX4 give none. The ranges are the twin's own (wide enough for any sensor the simulator draws);
//! a test narrows one ([`TwinConfig::ranges`]) to be refused.
//!
//! The link may lose messages ([`TwinConfig::loss`]: that share of the frames it sends, any message, drawn from a
//! seed), and the autopilot may reboot ([`TwinConfig::reboot_at_s`]): silent for [`BOOT_S`], it comes back with its
//! boot clock (`time_usec`, `time_boot_ms`) counting from the reboot, its streams at their defaults again (at
//! [`TwinConfig::rate_hz`], or none until asked again with [`TwinConfig::await_request`]) and its parameters as
//! they were (saved, as on the real autopilots). The bench and the hand go on through it.

use std::io::{ErrorKind, Read, Write};
use std::thread;
use std::time::{Duration, Instant};

use magcal_autopilot::link::FrameBuffer;
use magcal_autopilot::params::{from_wire, param_id, param_name, to_wire};
use magcal_autopilot::{Autopilot, ParamValue};
use magcal_sim::SimError;
use magcal_sim::bench::{Bench, BenchConfig};
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, BATTERY_STATUS_DATA, COMMAND_ACK_DATA, COMMAND_LONG_DATA,
    HEARTBEAT_DATA, HIGHRES_IMU_DATA, HighresImuUpdatedFlags, MavCmd, MavMessage, MavModeFlag,
    MavParamType, MavResult, MavState, MavType, PARAM_VALUE_DATA, RAW_IMU_DATA,
};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
// Deprecated by MAVLink (SET_MESSAGE_INTERVAL supersedes it), and still what ArduPilot's stream groups answer.
#[allow(deprecated)]
use mavlink::dialects::common::{MavDataStream, REQUEST_DATA_STREAM_DATA};
use mavlink::{MavHeader, MessageData};

/// A rate in words: whole hertz without decimals.
fn fmt_hz(hz: f64) -> String {
    if hz.fract() == 0.0 {
        format!("{hz:.0}")
    } else {
        format!("{hz:.2}")
    }
}

/// The battery current over bench time: a raised cosine between `idle_a` and `peak_a` with period `period_s` (a
/// hand raising and lowering the throttle), or constant when `period_s` is not positive; with [`blips`](Self::blips),
/// the hand then blips the throttle and leaves it at idle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentProfile {
    /// The lowest current, A.
    pub idle_a: f64,
    /// The highest current, A.
    pub peak_a: f64,
    /// The period of one rise and fall, s.
    pub period_s: f64,
    /// Quick throttle steps after a number of the slow ramps; `None`: the ramps go on.
    pub blips: Option<Blips>,
}

/// Throttle blips: the throttle snapped from idle to peak and back, the current following each step as a first-order
/// response (an ESC and its motor take it from idle to high in 50–150 ms: 10–90 % in 2.2 time constants).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blips {
    /// Whole periods of the slow ramps before the blips.
    pub after_ramps: u32,
    /// How many blips.
    pub count: u32,
    /// How long the throttle rests at idle before each blip, s.
    pub idle_s: f64,
    /// How long the throttle is held high in each blip, s.
    pub high_s: f64,
    /// The current's time constant after each step of the throttle, s.
    pub time_constant_s: f64,
}

impl CurrentProfile {
    /// Slow ramps only: the raised cosine from `idle_a` to `peak_a` every `period_s`, for ever.
    pub fn ramps(idle_a: f64, peak_a: f64, period_s: f64) -> CurrentProfile {
        CurrentProfile {
            idle_a,
            peak_a,
            period_s,
            blips: None,
        }
    }

    /// The current at `t_s` (the hand starts at 0: idle before), A.
    pub fn at(&self, t_s: f64) -> f64 {
        if self.period_s <= 0.0 || t_s < 0.0 {
            return self.idle_a;
        }
        let span_a = self.peak_a - self.idle_a;
        if let Some(b) = self.blips {
            let start_s = f64::from(b.after_ramps) * self.period_s;
            if t_s >= start_s {
                return self.idle_a + span_a * b.throttle_response(t_s - start_s);
            }
        }
        let phase = std::f64::consts::TAU * t_s / self.period_s;
        self.idle_a + span_a * (1.0 - phase.cos()) / 2.0
    }
}

impl Blips {
    /// The share of the step the current has reached `u_s` after the first blip's idle began: each step of the
    /// throttle (up at `idle_s` into a blip, down `high_s` later) adds or removes `1 − e^(−t/τ)`.
    fn throttle_response(&self, u_s: f64) -> f64 {
        let tau = self.time_constant_s.max(1e-9);
        let step = |since_s: f64| {
            if since_s > 0.0 {
                1.0 - (-since_s / tau).exp()
            } else {
                0.0
            }
        };
        let cycle_s = self.idle_s + self.high_s;
        (0..self.count)
            .map(|n| {
                let up_s = f64::from(n) * cycle_s + self.idle_s;
                step(u_s - up_s) - step(u_s - up_s - self.high_s)
            })
            .sum()
    }
}

/// What the twin is.
#[derive(Clone, Debug, PartialEq)]
pub struct TwinConfig {
    /// ArduPilot or PX4.
    pub autopilot: Autopilot,
    /// The bench its compass sits on; a `CurrentBias` on channel 0 follows [`current`](Self::current).
    pub bench: BenchConfig,
    /// The battery current; `None`: 0 A and no `BATTERY_STATUS`.
    pub current: Option<CurrentProfile>,
    /// How late the compass's field follows the battery current, s: the bench's effects are given the current of
    /// that long before (a `CurrentBias` gives `k·I(t − lag)`), while `BATTERY_STATUS` and the autopilot's own motor
    /// compensation carry `I(t)` (as its battery monitor measures it, [`battery_hz`](Self::battery_hz)). (A lag of
    /// the field the hand turns is the bench's `TimeLag` effect.)
    pub current_lag_s: f64,
    /// How often its battery monitor measures the current, Hz; 0: at every message. `BATTERY_STATUS` and the motor
    /// compensation carry the last measurement (ArduCopter reads its battery monitor at 10 Hz, whatever rate
    /// `BATTERY_STATUS` is streamed at).
    pub battery_hz: f64,
    /// When the hand starts the throttle profile: `None`, at boot; `Some(wait_s)`, that long (bench s) after a ground
    /// station first asks for `BATTERY_STATUS` (an operator waiting for the recorder's prompt), the current idle
    /// until then.
    pub throttle_after_request_s: Option<f64>,
    /// Compass, attitude and battery messages per second of bench time, Hz: the fastest it sends any of them (a
    /// request for more gets this).
    pub rate_hz: f64,
    /// Bench seconds per wall second (the port is a pseudo-terminal or memory, so faster than real time is fine).
    pub speed: f64,
    /// Whether it streams telemetry (otherwise only heartbeats and parameters, whatever is asked).
    pub stream: bool,
    /// Whether it waits for a ground station to ask for each stream (`REQUEST_DATA_STREAM`, ArduPilot only, or
    /// `SET_MESSAGE_INTERVAL`) before it sends it; otherwise every stream starts at [`rate_hz`](Self::rate_hz).
    pub await_request: bool,
    /// Parameter values other than the defaults, by name.
    pub values: Vec<(String, f64)>,
    /// Parameter ranges other than the defaults, by name: (min, max).
    pub ranges: Vec<(String, f64, f64)>,
    /// The vehicle held down (a bench motor test): the hand holds it still at its first attitude instead of
    /// turning it.
    pub held: bool,
    /// The share of the frames it sends that the link loses, 0–1 (each frame drawn independently).
    pub loss: f64,
    /// The seed the losses are drawn from.
    pub loss_seed: u64,
    /// The bench time at which it reboots, s; `None`: it does not.
    pub reboot_at_s: Option<f64>,
}

impl TwinConfig {
    /// `autopilot` on `bench`, no current (nor lag), streaming at 50 Hz, 10 times faster than real time, its calibration
    /// parameters at their defaults (no correction), turned by the hand.
    pub fn new(autopilot: Autopilot, bench: BenchConfig) -> TwinConfig {
        TwinConfig {
            autopilot,
            bench,
            current: None,
            current_lag_s: 0.0,
            battery_hz: 0.0,
            throttle_after_request_s: None,
            rate_hz: 50.0,
            speed: 10.0,
            stream: true,
            await_request: false,
            values: Vec::new(),
            ranges: Vec::new(),
            held: false,
            loss: 0.0,
            loss_seed: 0,
            reboot_at_s: None,
        }
    }

    /// Each stream's rate at boot, Hz: [`rate_hz`](Self::rate_hz), or 0 with [`await_request`](Self::await_request).
    fn boot_rate_hz(&self) -> f64 {
        if self.await_request {
            0.0
        } else {
            self.rate_hz
        }
    }
}

/// A twin that cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum TwinError {
    /// The bench's effects need what it does not have.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A value or range was given for a parameter it does not have.
    #[error("the {autopilot} twin has no parameter {name}")]
    NoParam {
        /// The autopilot.
        autopilot: Autopilot,
        /// The name given.
        name: String,
    },
}

/// One parameter the twin holds.
#[derive(Clone, Debug, PartialEq)]
struct Param {
    name: String,
    value: f64,
    kind: MavParamType,
    min: f64,
    max: f64,
}

const REAL: MavParamType = MavParamType::MAV_PARAM_TYPE_REAL32;

/// The parameters of `autopilot`, at their defaults, with the twin's ranges.
fn default_params(autopilot: Autopilot) -> Vec<Param> {
    let p = |name: &str, value: f64, kind, min: f64, max: f64| Param {
        name: name.to_owned(),
        value,
        kind,
        min,
        max,
    };
    let mut out = Vec::new();
    match autopilot {
        Autopilot::ArduPilot => {
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("COMPASS_OFS_{a}"), 0.0, REAL, -4000.0, 4000.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("COMPASS_DIA_{a}"), 1.0, REAL, 0.2, 5.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("COMPASS_ODI_{a}"), 0.0, REAL, -1.0, 1.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("COMPASS_MOT_{a}"), 0.0, REAL, -1000.0, 1000.0));
            }
            out.push(p(
                "COMPASS_MOTCT",
                0.0,
                MavParamType::MAV_PARAM_TYPE_INT8,
                0.0,
                3.0,
            ));
            out.push(p(
                "COMPASS_USE",
                1.0,
                MavParamType::MAV_PARAM_TYPE_INT8,
                0.0,
                1.0,
            ));
            out.push(p(
                "SYSID_THISMAV",
                1.0,
                MavParamType::MAV_PARAM_TYPE_INT16,
                1.0,
                255.0,
            ));
        }
        Autopilot::Px4 => {
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("CAL_MAG0_{a}OFF"), 0.0, REAL, -40.0, 40.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("CAL_MAG0_{a}SCALE"), 1.0, REAL, 0.2, 5.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("CAL_MAG0_{a}ODIAG"), 0.0, REAL, -1.0, 1.0));
            }
            for a in ["X", "Y", "Z"] {
                out.push(p(&format!("CAL_MAG0_{a}COMP"), 0.0, REAL, -1000.0, 1000.0));
            }
            out.push(p(
                "CAL_MAG_COMP_TYP",
                0.0,
                MavParamType::MAV_PARAM_TYPE_INT32,
                0.0,
                3.0,
            ));
            out.push(p(
                "CAL_MAG0_ID",
                396809.0,
                MavParamType::MAV_PARAM_TYPE_INT32,
                0.0,
                1e9,
            ));
            out.push(p(
                "MAV_SYS_ID",
                1.0,
                MavParamType::MAV_PARAM_TYPE_INT32,
                1.0,
                250.0,
            ));
        }
    }
    out
}

/// What one compass message carried, for a test to compare with what a tool saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sent {
    /// Bench time, s.
    pub t_s: f64,
    /// The sensor's raw reading (with noise), µT: what a tool must get back by undoing the autopilot's calibration.
    pub raw_ut: [f64; 3],
    /// The field sent, µT (after the autopilot's calibration, before the message's rounding).
    pub sent_ut: [f64; 3],
    /// The attitude, sensor (body) → NED, `[w, x, y, z]`.
    pub quat: [f64; 4],
    /// The battery current its battery monitor last measured ([`TwinConfig::battery_hz`]), A.
    pub current_a: f64,
}

/// What the twin did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TwinReport {
    /// Every compass message sent (put on the port).
    pub sent: Vec<Sent>,
    /// `PARAM_SET`s taken.
    pub sets_taken: u32,
    /// `PARAM_SET`s refused (answered with the old value).
    pub sets_refused: u32,
    /// `PARAM_SET`s and reads of a name it does not have (not answered).
    pub unknown_names: Vec<String>,
    /// Its parameters at the end, by name.
    pub params: Vec<(String, f64)>,
    /// Frames the port could not take (nobody read the other side), dropped.
    pub frames_dropped: u64,
    /// Frames the link lost ([`TwinConfig::loss`]).
    pub frames_lost: u64,
    /// When it rebooted, bench s.
    pub rebooted_at_s: Option<f64>,
    /// Stream requests taken, in words (`RAW_IMU at 50 Hz (asked 100 Hz)`).
    pub requests: Vec<String>,
    /// Why it stopped.
    pub stopped: String,
}

impl TwinReport {
    /// A parameter's value at the end.
    pub fn param(&self, name: &str) -> Option<f64> {
        self.params.iter().find(|(n, _)| n == name).map(|p| p.1)
    }
}

/// The twin; see the [module docs](self).
pub struct AutopilotTwin<P> {
    port: P,
    config: TwinConfig,
    bench: Bench,
    params: Vec<Param>,
    frames: FrameBuffer,
    sequence: u8,
    report: TwinReport,
    alive: bool,
    /// Each stream's rate, Hz (0: not sent), and when it is next due, bench s: the compass, the attitude, the
    /// battery.
    rates_hz: [f64; 3],
    due_s: [f64; 3],
    /// Bench time now, s.
    now_s: f64,
    /// The bench time its boot clock counts from, and the bench time from which it is up (sends and answers), s.
    boot_at_s: f64,
    up_at_s: f64,
    /// Draws the frames the link loses.
    loss_rng: ChaCha8Rng,
    /// The bench time the throttle profile starts at, s (`None`: not yet, waiting for a request).
    throttle_from_s: Option<f64>,
}

/// The streams the twin sends, by index into its rates.
const COMPASS: usize = 0;
const ATTITUDE: usize = 1;
const BATTERY: usize = 2;

/// The twin's own ids: system 1, component 1 (the autopilot).
const SYSTEM: u32 = 1;
const COMPONENT: u8 = 1;
/// How long a frame may wait for the port before it is dropped.
const SEND_TIMEOUT: Duration = Duration::from_millis(20);
/// How long a reboot keeps it silent, bench s.
pub const BOOT_S: f64 = 1.0;

impl<P: Read + Write> AutopilotTwin<P> {
    /// The twin on `port` (reads should not block long: a non-blocking pseudo-terminal master, or a
    /// [`magcal_autopilot::MemoryPort`] with a short timeout). Refuses a bench whose effects need channels other
    /// than the battery current, and parameter values or ranges of names it does not have.
    pub fn new(port: P, config: TwinConfig) -> Result<AutopilotTwin<P>, TwinError> {
        let mut bench = Bench::with_currents(config.bench.clone(), 1)?;
        if !config.held {
            bench.hand_mut().tumble(0.0, 1.0);
        }
        let mut params = default_params(config.autopilot);
        for (name, value) in &config.values {
            let p =
                params
                    .iter_mut()
                    .find(|p| &p.name == name)
                    .ok_or_else(|| TwinError::NoParam {
                        autopilot: config.autopilot,
                        name: name.clone(),
                    })?;
            p.value = *value;
        }
        for (name, min, max) in &config.ranges {
            let p =
                params
                    .iter_mut()
                    .find(|p| &p.name == name)
                    .ok_or_else(|| TwinError::NoParam {
                        autopilot: config.autopilot,
                        name: name.clone(),
                    })?;
            (p.min, p.max) = (*min, *max);
        }
        Ok(AutopilotTwin {
            loss_rng: magcal_sim::stream_rng(config.loss_seed, 0),
            throttle_from_s: config.throttle_after_request_s.is_none().then_some(0.0),
            rates_hz: [config.boot_rate_hz(); 3],
            port,
            config,
            bench,
            params,
            frames: FrameBuffer::new(),
            sequence: 0,
            due_s: [0.0; 3],
            now_s: 0.0,
            boot_at_s: 0.0,
            up_at_s: 0.0,
            report: TwinReport::default(),
            alive: true,
        })
    }

    /// A parameter's value now.
    fn value(&self, name: &str) -> f64 {
        self.params
            .iter()
            .find(|p| p.name == name)
            .map_or(0.0, |p| p.value)
    }

    /// Runs until `stop()` says so or the other side is gone; returns what it did.
    pub fn run(mut self, stop: impl Fn() -> bool) -> TwinReport {
        let start = Instant::now();
        let dt = 1.0 / self.config.rate_hz;
        let mut t_s = 0.0;
        let mut next_heartbeat_s = 0.0;
        self.report.stopped = loop {
            if !self.alive {
                break "the other side went away".to_owned();
            }
            if stop() {
                break "told to stop".to_owned();
            }
            let due = Duration::from_secs_f64(t_s / self.config.speed);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                thread::sleep(wait);
            }
            self.now_s = t_s;
            if self.report.rebooted_at_s.is_none()
                && self.config.reboot_at_s.is_some_and(|at| t_s >= at)
            {
                self.reboot(t_s);
            }
            self.receive();
            let up = t_s >= self.up_at_s;
            if t_s >= next_heartbeat_s {
                if up {
                    self.heartbeat();
                }
                next_heartbeat_s += 1.0;
            }
            if self.config.stream && up {
                self.telemetry(t_s);
            }
            t_s += dt;
        };
        self.report.params = self
            .params
            .iter()
            .map(|p| (p.name.clone(), p.value))
            .collect();
        self.report
    }

    /// Reboots at bench time `t_s`; see the [module docs](self).
    fn reboot(&mut self, t_s: f64) {
        self.boot_at_s = t_s;
        self.up_at_s = t_s + BOOT_S;
        self.rates_hz = [self.config.boot_rate_hz(); 3];
        self.due_s = [self.up_at_s; 3];
        self.sequence = 0;
        self.frames = FrameBuffer::new();
        self.report.rebooted_at_s = Some(t_s);
    }

    /// Sends `msg`; returns whether it went on the port (not lost by the link, nor dropped for a full port).
    fn send(&mut self, msg: &MavMessage) -> bool {
        let header = MavHeader {
            system_id: SYSTEM,
            component_id: COMPONENT,
            sequence: self.sequence,
        };
        // The autopilot numbers every frame it sends; the link loses some of them.
        self.sequence = self.sequence.wrapping_add(1);
        if self.config.loss > 0.0 && self.loss_rng.random_bool(self.config.loss.min(1.0)) {
            self.report.frames_lost += 1;
            return false;
        }
        let mut bytes = Vec::with_capacity(64);
        mavlink::write_v2_msg(&mut bytes, header, msg).expect("writing to a Vec");
        let mut at = 0;
        let deadline = Instant::now() + SEND_TIMEOUT;
        while at < bytes.len() {
            match self.port.write(&bytes[at..]) {
                Ok(0) => {
                    self.alive = false;
                    return false;
                }
                Ok(n) => at += n,
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                    if Instant::now() >= deadline {
                        self.report.frames_dropped += 1;
                        return false;
                    }
                    thread::sleep(Duration::from_millis(1));
                }
                Err(_) => {
                    self.alive = false;
                    return false;
                }
            }
        }
        let _ = self.port.flush();
        true
    }

    fn heartbeat(&mut self) {
        let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: self.config.autopilot.field(),
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        });
        self.send(&msg);
    }

    /// The compass, attitude and battery messages at `t_s`.
    fn telemetry(&mut self, t_s: f64) {
        let mut due = [false; 3];
        for (k, d) in due.iter_mut().enumerate() {
            let rate = self.rates_hz[k];
            if rate > 0.0 && t_s + 1e-9 >= self.due_s[k] {
                *d = true;
                self.due_s[k] = (self.due_s[k] + 1.0 / rate).max(t_s + 0.5 / rate);
            }
        }
        if due == [false; 3] {
            return;
        }
        let from_s = self.throttle_from_s.unwrap_or(f64::INFINITY);
        let current_at = |t_s: f64| self.config.current.map_or(0.0, |c| c.at(t_s - from_s));
        let measured_s = if self.config.battery_hz > 0.0 {
            (t_s * self.config.battery_hz).floor() / self.config.battery_hz
        } else {
            t_s
        };
        let current_a = current_at(measured_s);
        let s = self
            .bench
            .sample_with_currents(t_s, &[current_at(t_s - self.config.current_lag_s)]);
        let v = |n: &str| self.value(n);
        let boot_s = t_s - self.boot_at_s;
        let time_usec = (boot_s * 1e6) as u64;
        let (msg, sent_ut) = match self.config.autopilot {
            Autopilot::ArduPilot => {
                let raw = s.raw_ut.map(|x| x * 10.0);
                let ofs = [v("COMPASS_OFS_X"), v("COMPASS_OFS_Y"), v("COMPASS_OFS_Z")];
                let (d, o) = (
                    [v("COMPASS_DIA_X"), v("COMPASS_DIA_Y"), v("COMPASS_DIA_Z")],
                    [v("COMPASS_ODI_X"), v("COMPASS_ODI_Y"), v("COMPASS_ODI_Z")],
                );
                let m = [[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]];
                let x: [f64; 3] = std::array::from_fn(|k| raw[k] + ofs[k]);
                let motct = v("COMPASS_MOTCT").round() as i64;
                let mot = [v("COMPASS_MOT_X"), v("COMPASS_MOT_Y"), v("COMPASS_MOT_Z")];
                let mg: [f64; 3] = std::array::from_fn(|j| {
                    (0..3).map(|k| m[j][k] * x[k]).sum::<f64>()
                        + if motct == 2 { mot[j] * current_a } else { 0.0 }
                });
                let [xmag, ymag, zmag] =
                    mg.map(|f| f.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16);
                let centi = (s.temp_c * 100.0).round() as i16;
                (
                    MavMessage::RAW_IMU(RAW_IMU_DATA {
                        time_usec,
                        xmag,
                        ymag,
                        zmag,
                        id: 0,
                        temperature: if centi == 0 { 1 } else { centi },
                        ..RAW_IMU_DATA::default()
                    }),
                    mg.map(|f| f / 10.0),
                )
            }
            Autopilot::Px4 => {
                let raw = s.raw_ut.map(|x| x / 100.0);
                let off = [v("CAL_MAG0_XOFF"), v("CAL_MAG0_YOFF"), v("CAL_MAG0_ZOFF")];
                let (d, o) = (
                    [
                        v("CAL_MAG0_XSCALE"),
                        v("CAL_MAG0_YSCALE"),
                        v("CAL_MAG0_ZSCALE"),
                    ],
                    [
                        v("CAL_MAG0_XODIAG"),
                        v("CAL_MAG0_YODIAG"),
                        v("CAL_MAG0_ZODIAG"),
                    ],
                );
                let m = [[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]];
                let comp_typ = v("CAL_MAG_COMP_TYP").round() as i64;
                let comp = [
                    v("CAL_MAG0_XCOMP"),
                    v("CAL_MAG0_YCOMP"),
                    v("CAL_MAG0_ZCOMP"),
                ];
                let power = if comp_typ == 2 {
                    current_a / 1000.0
                } else {
                    0.0
                };
                let x: [f64; 3] = std::array::from_fn(|k| raw[k] + power * comp[k] - off[k]);
                let g: [f64; 3] = std::array::from_fn(|j| (0..3).map(|k| m[j][k] * x[k]).sum());
                (
                    MavMessage::HIGHRES_IMU(HIGHRES_IMU_DATA {
                        time_usec,
                        xmag: g[0] as f32,
                        ymag: g[1] as f32,
                        zmag: g[2] as f32,
                        temperature: s.temp_c as f32,
                        fields_updated: HighresImuUpdatedFlags::from_bits_truncate(0x1c0 | 0x1000),
                        id: 0,
                        ..HIGHRES_IMU_DATA::default()
                    }),
                    g.map(|f| f * 100.0),
                )
            }
        };
        if due[COMPASS] && self.send(&msg) {
            self.report.sent.push(Sent {
                t_s,
                raw_ut: s.raw_ut,
                sent_ut,
                quat: s.quat,
                current_a,
            });
        }
        let [w, x, y, z] = s.quat.map(|q| q as f32);
        if due[ATTITUDE] {
            self.send(&MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                time_boot_ms: (boot_s * 1000.0) as u32,
                q1: w,
                q2: x,
                q3: y,
                q4: z,
                ..ATTITUDE_QUATERNION_DATA::default()
            }));
        }
        if due[BATTERY] && self.config.current.is_some() {
            self.send(&MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
                current_battery: (current_a * 100.0).round() as i16,
                id: 0,
                ..BATTERY_STATUS_DATA::default()
            }));
        }
    }

    /// The stream a message id is sent in, if the twin sends it.
    fn stream_of(&self, message_id: u32) -> Option<usize> {
        let compass = match self.config.autopilot {
            Autopilot::ArduPilot => RAW_IMU_DATA::ID,
            Autopilot::Px4 => HIGHRES_IMU_DATA::ID,
        };
        match message_id {
            id if id == compass => Some(COMPASS),
            ATTITUDE_QUATERNION_DATA::ID => Some(ATTITUDE),
            BATTERY_STATUS_DATA::ID => Some(BATTERY),
            _ => None,
        }
    }

    /// Sets stream `k` to `asked_hz` (0: off), at most the twin's rate, from now on; notes it as `name`.
    fn set_rate(&mut self, k: usize, asked_hz: f64, name: &str) {
        let got = asked_hz.clamp(0.0, self.config.rate_hz);
        self.rates_hz[k] = got;
        self.due_s[k] = self.now_s;
        if k == BATTERY && got > 0.0 && self.throttle_from_s.is_none() {
            self.throttle_from_s =
                Some(self.now_s + self.config.throttle_after_request_s.unwrap_or(0.0));
        }
        self.report.requests.push(format!(
            "{name} at {} Hz (asked {} Hz)",
            fmt_hz(got),
            fmt_hz(asked_hz)
        ));
    }

    /// `REQUEST_DATA_STREAM` (ArduPilot's stream groups; PX4 ignores it): `RAW_SENSORS` holds `RAW_IMU`,
    /// `EXTENDED_STATUS` `BATTERY_STATUS`, `ALL` both. `ATTITUDE_QUATERNION` is in no group (ArduPilot sends it only
    /// when asked for by `SET_MESSAGE_INTERVAL`). MAVLink deprecates the message; ArduPilot still takes it.
    #[allow(deprecated)]
    fn request_data_stream(&mut self, r: &REQUEST_DATA_STREAM_DATA) {
        if self.config.autopilot != Autopilot::ArduPilot {
            return;
        }
        let hz = if r.start_stop == 0 {
            0.0
        } else {
            f64::from(r.req_message_rate)
        };
        let streams: &[(usize, &str)] = match r.req_stream_id {
            MavDataStream::MAV_DATA_STREAM_RAW_SENSORS => &[(COMPASS, "RAW_IMU")],
            MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS => &[(BATTERY, "BATTERY_STATUS")],
            MavDataStream::MAV_DATA_STREAM_ALL => {
                &[(COMPASS, "RAW_IMU"), (BATTERY, "BATTERY_STATUS")]
            }
            _ => &[],
        };
        for (k, name) in streams {
            self.set_rate(*k, hz, name);
        }
    }

    /// `COMMAND_LONG` `SET_MESSAGE_INTERVAL` (param1 the message id, param2 the interval in µs: −1 off, 0 the
    /// default rate), answered with `COMMAND_ACK`; any other command is answered `UNSUPPORTED`.
    fn command(&mut self, c: &COMMAND_LONG_DATA) {
        let result = if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL {
            let id = c.param1.round() as u32;
            match self.stream_of(id) {
                Some(k) => {
                    let interval_us = f64::from(c.param2);
                    let hz = if interval_us < 0.0 {
                        0.0
                    } else if interval_us == 0.0 {
                        self.config.rate_hz
                    } else {
                        1e6 / interval_us
                    };
                    let name = match k {
                        COMPASS => "the compass message",
                        ATTITUDE => "ATTITUDE_QUATERNION",
                        _ => "BATTERY_STATUS",
                    };
                    self.set_rate(k, hz, name);
                    MavResult::MAV_RESULT_ACCEPTED
                }
                None => MavResult::MAV_RESULT_FAILED,
            }
        } else {
            MavResult::MAV_RESULT_UNSUPPORTED
        };
        self.send(&MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: c.command,
            result,
            ..COMMAND_ACK_DATA::default()
        }));
    }

    /// Takes what arrived and answers the parameter requests among it.
    fn receive(&mut self) {
        let mut buf = [0u8; 512];
        loop {
            match self.port.read(&mut buf) {
                Ok(0) => {
                    self.alive = false;
                    break;
                }
                Ok(n) => self.frames.push(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) =>
                {
                    break;
                }
                Err(_) => {
                    self.alive = false;
                    break;
                }
            }
        }
        while let Some((_, msg)) = self.frames.next_message() {
            self.handle(&msg);
        }
    }

    fn param_value(&self, index: usize) -> MavMessage {
        let p = &self.params[index];
        MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: to_wire(self.config.autopilot, p.kind, p.value),
            param_count: self.params.len() as u16,
            param_index: index as u16,
            param_id: param_id(&p.name).into(),
            param_type: p.kind,
        })
    }

    fn index_of(&self, name: &str) -> Option<usize> {
        self.params.iter().position(|p| p.name == name)
    }

    #[allow(deprecated)] // REQUEST_DATA_STREAM, which ArduPilot still takes
    fn handle(&mut self, msg: &MavMessage) {
        if self.now_s < self.up_at_s {
            return; // booting: nothing listens
        }
        match msg {
            MavMessage::REQUEST_DATA_STREAM(r) => self.request_data_stream(r),
            MavMessage::COMMAND_LONG(c) => self.command(c),
            MavMessage::PARAM_REQUEST_LIST(_) => {
                for i in 0..self.params.len() {
                    let m = self.param_value(i);
                    self.send(&m);
                }
            }
            MavMessage::PARAM_REQUEST_READ(r) => {
                let index = if r.param_index >= 0 {
                    Some(r.param_index as usize).filter(|i| *i < self.params.len())
                } else {
                    let name = param_name(&r.param_id[..]);
                    let found = self.index_of(&name);
                    if found.is_none() {
                        self.report.unknown_names.push(name);
                    }
                    found
                };
                if let Some(i) = index {
                    let m = self.param_value(i);
                    self.send(&m);
                }
            }
            MavMessage::PARAM_SET(set) => {
                let name = param_name(&set.param_id[..]);
                let Some(i) = self.index_of(&name) else {
                    self.report.unknown_names.push(name);
                    return;
                };
                let p = &mut self.params[i];
                let value = from_wire(self.config.autopilot, p.kind, set.param_value);
                if value.is_finite() && (p.min..=p.max).contains(&value) {
                    p.value = if p.kind == REAL {
                        f64::from(value as f32)
                    } else {
                        value
                    };
                    self.report.sets_taken += 1;
                } else {
                    self.report.sets_refused += 1;
                }
                let m = self.param_value(i);
                self.send(&m);
            }
            _ => {}
        }
    }
}

/// The parameters a twin holds, as [`ParamValue`]s (for comparing with what a tool read).
pub fn values_of(report: &TwinReport, autopilot: Autopilot) -> Vec<ParamValue> {
    let defaults = default_params(autopilot);
    report
        .params
        .iter()
        .enumerate()
        .map(|(i, (name, value))| {
            let kind = defaults[i].kind;
            ParamValue {
                name: name.clone(),
                value: *value,
                wire: to_wire(autopilot, kind, *value),
                kind,
                index: i as u16,
                count: report.params.len() as u16,
            }
        })
        .collect()
}
