//! The MAVLink parameter protocol (<https://mavlink.io/en/services/parameter.html>): read a parameter
//! (`PARAM_REQUEST_READ` → `PARAM_VALUE`), list them all (`PARAM_REQUEST_LIST`), set one (`PARAM_SET` →
//! `PARAM_VALUE`, which carries the value the autopilot holds afterwards: the new one, or the old one when it
//! refused); and on top of it a write-back that either sets every parameter and reads each back, or leaves the
//! autopilot with the values it had ([`write_all`]); and the `.param` files that hold parameters
//! ([`param_file`], [`parse_param_file`]).
//!
//! Values travel as a float. A float parameter is that float; an integer is its value cast to float for ArduPilot,
//! and its bytes in the float's place for PX4 (MAVLink's "bytewise" encoding, `MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE`):
//! [`to_wire`] and [`from_wire`].

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
    PARAM_VALUE_DATA,
};

use crate::link::{Autopilot, Connection, LinkError};

/// How long one request waits for its `PARAM_VALUE`.
pub const ANSWER_TIMEOUT: Duration = Duration::from_millis(1000);
/// How many times a request is sent before a parameter counts as unanswered.
pub const TRIES: u32 = 3;

/// A parameter as the autopilot holds it.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamValue {
    /// Its name (at most 16 bytes).
    pub name: String,
    /// Its value, decoded ([`from_wire`]).
    pub value: f64,
    /// The float that carried it.
    pub wire: f32,
    /// Its type.
    pub kind: MavParamType,
    /// Its index.
    pub index: u16,
    /// How many parameters the autopilot has.
    pub count: u16,
}

/// Whether `kind` is an integer type.
fn is_integer(kind: MavParamType) -> bool {
    !matches!(
        kind,
        MavParamType::MAV_PARAM_TYPE_REAL32 | MavParamType::MAV_PARAM_TYPE_REAL64
    )
}

/// The float that carries `value` of type `kind` to `autopilot`.
pub fn to_wire(autopilot: Autopilot, kind: MavParamType, value: f64) -> f32 {
    match (autopilot, is_integer(kind)) {
        (_, false) => value as f32,
        (Autopilot::ArduPilot, true) => value.round() as f32,
        (Autopilot::Px4, true) => f32::from_bits(value.round() as i32 as u32),
    }
}

/// The value of type `kind` that the float `wire` from `autopilot` carries.
pub fn from_wire(autopilot: Autopilot, kind: MavParamType, wire: f32) -> f64 {
    match (autopilot, is_integer(kind)) {
        (_, false) => f64::from(wire),
        (Autopilot::ArduPilot, true) => f64::from(wire).round(),
        (Autopilot::Px4, true) => f64::from(wire.to_bits() as i32),
    }
}

/// A parameter's 16-byte id.
pub fn param_id(name: &str) -> [u8; 16] {
    let mut id = [0u8; 16];
    for (slot, b) in id.iter_mut().zip(name.bytes()) {
        *slot = b;
    }
    id
}

/// A parameter's name: its 16 bytes up to the first NUL.
pub fn param_name(id: &[u8]) -> String {
    let end = id.iter().position(|b| *b == 0).unwrap_or(id.len());
    String::from_utf8_lossy(&id[..end]).into_owned()
}

/// A parameter request that got no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// The link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// No `PARAM_VALUE` for it came back.
    #[error(
        "no PARAM_VALUE for {name} came back to {request} ({tries} tries, {timeout_s:.1} s each){hint}"
    )]
    NoAnswer {
        /// The parameter.
        name: String,
        /// What was sent.
        request: &'static str,
        /// How many times.
        tries: u32,
        /// How long each waited, s.
        timeout_s: f64,
        /// What it likely means.
        hint: &'static str,
    },
    /// No heartbeat has told whom to ask.
    #[error("no autopilot to ask: wait for its heartbeat first")]
    NoTarget,
}

impl<P: Read + Write> Connection<P> {
    fn target_or_err(&self) -> Result<(u8, u8, Autopilot), ParamError> {
        match (self.target(), self.autopilot()) {
            (Some((s, c)), Some(a)) => Ok((s, c, a)),
            _ => Err(ParamError::NoTarget),
        }
    }

    /// Sends `request` up to [`TRIES`] times until a `PARAM_VALUE` named `name` comes back.
    fn ask(
        &mut self,
        name: &str,
        request: &MavMessage,
        what: &'static str,
        hint: &'static str,
    ) -> Result<ParamValue, ParamError> {
        let (_, _, autopilot) = self.target_or_err()?;
        for _ in 0..TRIES {
            self.send(request)?;
            let deadline = Instant::now() + ANSWER_TIMEOUT;
            while let Some((header, msg)) = self.next_message(deadline)? {
                if let MavMessage::PARAM_VALUE(v) = &msg
                    && param_name(&v.param_id[..]) == name
                {
                    return Ok(value_of(autopilot, v));
                }
                self.keep((header, msg));
            }
        }
        Err(ParamError::NoAnswer {
            name: name.to_owned(),
            request: what,
            tries: TRIES,
            timeout_s: ANSWER_TIMEOUT.as_secs_f64(),
            hint,
        })
    }

    /// Reads the parameter `name` if the autopilot has it: one `PARAM_REQUEST_READ` by name, its answer waited for
    /// [`ANSWER_TIMEOUT`]; `None` when none came (a parameter another firmware version lacks).
    pub fn read_param_if_any(&mut self, name: &str) -> Result<Option<ParamValue>, ParamError> {
        let (target_system, target_component, autopilot) = self.target_or_err()?;
        self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system,
            target_component,
            param_id: param_id(name).into(),
        }))?;
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        while let Some((header, msg)) = self.next_message(deadline)? {
            if let MavMessage::PARAM_VALUE(v) = &msg
                && param_name(&v.param_id[..]) == name
            {
                return Ok(Some(value_of(autopilot, v)));
            }
            self.keep((header, msg));
        }
        Ok(None)
    }

    /// Reads the parameter `name` (`PARAM_REQUEST_READ` by name).
    pub fn read_param(&mut self, name: &str) -> Result<ParamValue, ParamError> {
        let (target_system, target_component, _) = self.target_or_err()?;
        let request = MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system,
            target_component,
            param_id: param_id(name).into(),
        });
        self.ask(
            name,
            &request,
            "PARAM_REQUEST_READ",
            ": the autopilot has no such parameter (another firmware version, or the feature not built in?)",
        )
    }

    /// Sets the parameter `name` of type `kind` to `value` (`PARAM_SET`) and returns what the autopilot answered it
    /// holds: `value`, or its old value when it refused.
    pub fn set_param(
        &mut self,
        name: &str,
        value: f64,
        kind: MavParamType,
    ) -> Result<ParamValue, ParamError> {
        let (target_system, target_component, autopilot) = self.target_or_err()?;
        let request = MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: to_wire(autopilot, kind, value),
            target_system,
            target_component,
            param_id: param_id(name).into(),
            param_type: kind,
        });
        self.ask(
            name,
            &request,
            "PARAM_SET",
            ": the autopilot did not confirm it (no such parameter, or the link lost the answer)",
        )
    }

    /// Every parameter (`PARAM_REQUEST_LIST`), in index order; those the link lost are asked for by index.
    pub fn list_params(&mut self) -> Result<Vec<ParamValue>, ParamError> {
        let (target_system, target_component, autopilot) = self.target_or_err()?;
        self.send(&MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system,
            target_component,
        }))?;
        let mut got: Vec<Option<ParamValue>> = Vec::new();
        let mut deadline = Instant::now() + ANSWER_TIMEOUT;
        let mut asked_again = 0;
        loop {
            match self.next_message(deadline)? {
                Some((_, MavMessage::PARAM_VALUE(v))) => {
                    let p = value_of(autopilot, &v);
                    if got.len() < usize::from(p.count) {
                        got.resize(usize::from(p.count), None);
                    }
                    if let Some(slot) = got.get_mut(usize::from(p.index)) {
                        *slot = Some(p);
                    }
                    deadline = Instant::now() + ANSWER_TIMEOUT;
                    if !got.is_empty() && got.iter().all(Option::is_some) {
                        break;
                    }
                }
                Some(other) => self.keep(other),
                None => {
                    let missing: Vec<usize> =
                        (0..got.len()).filter(|i| got[*i].is_none()).collect();
                    if got.is_empty() || missing.is_empty() || asked_again >= TRIES {
                        break;
                    }
                    asked_again += 1;
                    for i in missing {
                        self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                            param_index: i as i16,
                            target_system,
                            target_component,
                            param_id: [0u8; 16].into(),
                        }))?;
                    }
                    deadline = Instant::now() + ANSWER_TIMEOUT;
                }
            }
        }
        Ok(got.into_iter().flatten().collect())
    }
}

fn value_of(autopilot: Autopilot, v: &PARAM_VALUE_DATA) -> ParamValue {
    ParamValue {
        name: param_name(&v.param_id[..]),
        value: from_wire(autopilot, v.param_type, v.param_value),
        wire: v.param_value,
        kind: v.param_type,
        index: v.param_index,
        count: v.param_count,
    }
}

/// Whether the autopilot holds `wanted` when it answers `held`: the same float on the wire.
fn holds(autopilot: Autopilot, held: &ParamValue, wanted: f64) -> bool {
    held.wire.to_bits() == to_wire(autopilot, held.kind, wanted).to_bits()
        || (held.wire == 0.0 && to_wire(autopilot, held.kind, wanted) == 0.0)
}

/// Reads every parameter of `names`, in that order; the first that does not come back is the error.
pub fn read_all<P: Read + Write>(
    conn: &mut Connection<P>,
    names: &[&str],
) -> Result<Vec<ParamValue>, ParamError> {
    names.iter().map(|n| conn.read_param(n)).collect()
}

/// A write-back that did not go through: which parameter, why, and what became of those written before it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}", self.message())]
pub struct WriteFailure {
    /// The parameter that failed.
    pub param: String,
    /// Why.
    pub why: String,
    /// The parameters set to their previous values again (confirmed).
    pub restored: Vec<String>,
    /// The parameters that could not be set back, each with why.
    pub unrestored: Vec<(String, String)>,
}

impl WriteFailure {
    fn message(&self) -> String {
        let mut out = format!("{}: {}; ", self.param, self.why);
        if self.unrestored.is_empty() {
            if self.restored.is_empty() {
                out += "nothing had been changed: the autopilot keeps its previous values";
            } else {
                out += &format!(
                    "the {} parameter(s) already written were set back to their previous values and confirmed \
                     ({}): the autopilot keeps its previous values",
                    self.restored.len(),
                    self.restored.join(", ")
                );
            }
        } else {
            let list: Vec<String> = self
                .unrestored
                .iter()
                .map(|(n, why)| format!("{n} ({why})"))
                .collect();
            out += &format!(
                "and {} parameter(s) could NOT be set back: {}; load the undo file to restore them",
                self.unrestored.len(),
                list.join(", ")
            );
        }
        out
    }
}

/// Sets every parameter of `wanted` (name, value), confirming each by the `PARAM_VALUE` it answers, then reads each
/// back. `previous` holds what the autopilot had (from [`read_all`]; it gives each parameter's type). Anything
/// refused (answered with another value), unanswered or read back otherwise stops the write-back: the parameters
/// written so far, and the one that failed unless it answered with its previous value, are set back to their
/// `previous` values, and the error says which
/// parameter, why, and what was restored. Returns what was read back.
pub fn write_all<P: Read + Write>(
    conn: &mut Connection<P>,
    wanted: &[(String, f64)],
    previous: &[ParamValue],
) -> Result<Vec<ParamValue>, WriteFailure> {
    let Some(autopilot) = conn.autopilot() else {
        return Err(WriteFailure {
            param: wanted.first().map_or(String::new(), |w| w.0.clone()),
            why: ParamError::NoTarget.to_string(),
            restored: Vec::new(),
            unrestored: Vec::new(),
        });
    };
    let before = |name: &str| previous.iter().find(|p| p.name == name);
    let mut touched: Vec<&ParamValue> = Vec::new();
    let mut failure: Option<(String, String)> = None;
    for (name, value) in wanted {
        let Some(old) = before(name) else {
            failure = Some((name.clone(), "its previous value was not read".to_owned()));
            break;
        };
        touched.push(old);
        match conn.set_param(name, *value, old.kind) {
            Ok(held) if holds(autopilot, &held, *value) => {}
            Ok(held) => {
                if holds(autopilot, &held, old.value) {
                    // Refused, and still holding its previous value: nothing to set back.
                    touched.pop();
                }
                failure = Some((
                    name.clone(),
                    format!(
                        "the autopilot refused {value} (it answered that it holds {}: out of its range?)",
                        held.value
                    ),
                ));
                break;
            }
            Err(e) => {
                failure = Some((name.clone(), format!("not confirmed: {e}")));
                break;
            }
        }
    }
    let mut read_back = Vec::new();
    if failure.is_none() {
        for (name, value) in wanted {
            match conn.read_param(name) {
                Ok(held) if holds(autopilot, &held, *value) => read_back.push(held),
                Ok(held) => {
                    failure = Some((
                        name.clone(),
                        format!("set to {value}, it reads back {}", held.value),
                    ));
                    break;
                }
                Err(e) => {
                    failure = Some((name.clone(), format!("not read back: {e}")));
                    break;
                }
            }
        }
    }
    let Some((param, why)) = failure else {
        return Ok(read_back);
    };
    let mut restored = Vec::new();
    let mut unrestored = Vec::new();
    for old in touched {
        match conn.set_param(&old.name, old.value, old.kind) {
            Ok(held) if holds(autopilot, &held, old.value) => restored.push(old.name.clone()),
            Ok(held) => unrestored.push((old.name.clone(), format!("it holds {}", held.value))),
            Err(e) => unrestored.push((old.name.clone(), e.to_string())),
        }
    }
    Err(WriteFailure {
        param,
        why,
        restored,
        unrestored,
    })
}

/// A parameter file for `autopilot`: ArduPilot's `.param` (`NAME,VALUE`, as Mission Planner and MAVProxy load it),
/// PX4's QGroundControl `.params` (`1\t1\tNAME\tVALUE\tTYPE`); `comments` first, as `#` lines. Each value is
/// written with the digits that give back its float exactly.
pub fn param_file(autopilot: Autopilot, values: &[ParamValue], comments: &[String]) -> String {
    let mut out = String::new();
    for c in comments {
        out += &format!("# {c}\n");
    }
    if autopilot == Autopilot::Px4 {
        out += "# Vehicle-Id\tComponent-Id\tName\tValue\tType\n";
    }
    for p in values {
        let value = if is_integer(p.kind) {
            format!("{}", p.value as i64)
        } else {
            format!("{}", p.value as f32)
        };
        match autopilot {
            Autopilot::ArduPilot => out += &format!("{},{value}\n", p.name),
            Autopilot::Px4 => out += &format!("1\t1\t{}\t{value}\t{}\n", p.name, p.kind as u32),
        }
    }
    out
}

/// The parameters of a `.param` / `.params` file (ArduPilot's `NAME,VALUE` or `NAME VALUE`, QGroundControl's
/// tab-separated `SYS COMP NAME VALUE TYPE`); `#` lines are comments. The error names the line.
pub fn parse_param_file(text: &str) -> Result<Vec<(String, f64)>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = if line.contains('\t') {
            line.split('\t').map(str::trim).collect()
        } else if line.contains(',') {
            line.split(',').map(str::trim).collect()
        } else {
            line.split_whitespace().collect()
        };
        let (name, value) = match fields.len() {
            2 => (fields[0], fields[1]),
            5 => (fields[2], fields[3]),
            _ => {
                return Err(format!(
                    "line {}: {line:?} is neither NAME,VALUE nor SYS COMP NAME VALUE TYPE",
                    i + 1
                ));
            }
        };
        let value: f64 = value
            .parse()
            .map_err(|_| format!("line {}: {value:?} is not a number", i + 1))?;
        if name.is_empty() || name.len() > 16 {
            return Err(format!(
                "line {}: {name:?} is no parameter name (1–16 characters)",
                i + 1
            ));
        }
        out.push((name.to_owned(), value));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_travel_cast_for_ardupilot_and_bytewise_for_px4() {
        let int = MavParamType::MAV_PARAM_TYPE_INT32;
        assert_eq!(to_wire(Autopilot::ArduPilot, int, 2.0), 2.0);
        assert_eq!(to_wire(Autopilot::Px4, int, 2.0).to_bits(), 2);
        for a in [Autopilot::ArduPilot, Autopilot::Px4] {
            assert_eq!(from_wire(a, int, to_wire(a, int, -7.0)), -7.0);
            let real = MavParamType::MAV_PARAM_TYPE_REAL32;
            assert_eq!(from_wire(a, real, to_wire(a, real, 0.1)), f64::from(0.1f32));
        }
    }

    #[test]
    fn param_files_read_back_what_they_hold() {
        let p = |name: &str, value: f64, kind| ParamValue {
            name: name.to_owned(),
            value,
            wire: value as f32,
            kind,
            index: 0,
            count: 2,
        };
        let values = [
            p(
                "COMPASS_OFS_X",
                f64::from(-123.456f32),
                MavParamType::MAV_PARAM_TYPE_REAL32,
            ),
            p("CAL_MAG_COMP_TYP", 2.0, MavParamType::MAV_PARAM_TYPE_INT32),
        ];
        for a in [Autopilot::ArduPilot, Autopilot::Px4] {
            let text = param_file(a, &values, &["undo".to_owned()]);
            let back = parse_param_file(&text).unwrap();
            assert_eq!(back.len(), 2, "{text}");
            assert_eq!(back[0].0, "COMPASS_OFS_X");
            assert_eq!(back[0].1 as f32, -123.456f32, "{text}");
            assert_eq!(back[1], ("CAL_MAG_COMP_TYP".to_owned(), 2.0));
        }
        assert!(
            parse_param_file("A,B,C\n")
                .unwrap_err()
                .starts_with("line 1:")
        );
        assert_eq!(
            parse_param_file("COMPASS_DIA_X 1.01\n").unwrap(),
            [("COMPASS_DIA_X".to_owned(), 1.01)]
        );
    }
}
