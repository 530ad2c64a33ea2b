//! Acceptance (issue 35, 4): MAVLink bytes produced by an implementation magcal did not write — pymavlink 2.4.50,
//! by `fixtures/mavlink/make_fixture.py` — decode to the values they were given, in physical units: MAVLink 2 frames
//! (with their trailing zero bytes cut, as MAVLink 2 sends them) and a MAVLink 1 frame, every message a calibration
//! reads from ArduPilot and PX4.

use std::path::PathBuf;

use magcal_autopilot::{Telemetry, read_stream};
use mavlink::Message;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/mavlink")
        .join(name)
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance || (a.is_nan() && b.is_nan())
}

#[test]
fn pymavlink_bytes_decode_to_the_values_they_were_given() {
    let bytes = std::fs::read(fixture("telemetry.bin")).unwrap();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("telemetry.json")).unwrap()).unwrap();
    let expected = expected["messages"].as_array().unwrap();
    let decoded = read_stream(&bytes, "telemetry.bin").unwrap();
    assert_eq!(decoded.len(), expected.len(), "one message per frame");
    for ((msg, sample), want) in decoded.iter().zip(expected) {
        assert_eq!(msg.message_name(), want["message"].as_str().unwrap());
        let w = &want["want"];
        let sample = sample
            .as_ref()
            .unwrap_or_else(|| panic!("{} carries a sample", msg.message_name()));
        match (w["kind"].as_str().unwrap(), sample) {
            (
                "mag",
                Telemetry::Mag {
                    instance,
                    field_ut,
                    temp_c,
                    t_s,
                },
            ) => {
                assert_eq!(u64::from(*instance), w["instance"].as_u64().unwrap());
                for (got, want) in field_ut.iter().zip(floats(&w["field_ut"])) {
                    // HIGHRES_IMU sends f32 gauss: a few nT of rounding.
                    assert!(close(*got, want, 1e-4), "{field_ut:?} {w}");
                }
                assert!(
                    close(*temp_c, w["temp_c"].as_f64().unwrap(), 1e-9),
                    "{temp_c} {w}"
                );
                assert!(close(*t_s, w["t_s"].as_f64().unwrap(), 1e-9), "{t_s} {w}");
            }
            ("attitude", Telemetry::Attitude { q, t_s }) => {
                for (got, want) in q.iter().zip(floats(&w["q"])) {
                    assert!(close(*got, want, 1e-6), "{q:?} {w}");
                }
                assert!(close(*t_s, w["t_s"].as_f64().unwrap(), 1e-9));
            }
            ("current", Telemetry::Current { current_a }) => {
                assert!(
                    close(*current_a, w["current_a"].as_f64().unwrap(), 1e-9),
                    "{current_a} {w}"
                );
            }
            ("param", Telemetry::Param { name, value }) => {
                assert_eq!(name, w["name"].as_str().unwrap());
                assert!(close(*value, w["value"].as_f64().unwrap(), 1e-9));
            }
            (kind, got) => panic!("{kind}: {got:?}"),
        }
    }
}

#[test]
fn a_damaged_frame_is_skipped_and_the_rest_read() {
    let mut bytes = std::fs::read(fixture("telemetry.bin")).unwrap();
    // A byte of the first frame's payload changed: its checksum fails.
    bytes[15] ^= 0x5a;
    let decoded = read_stream(&bytes, "telemetry.bin").unwrap();
    assert_eq!(decoded.len(), 9, "the other nine frames");
    assert_eq!(decoded[0].0.message_name(), "RAW_IMU");
    assert!(matches!(
        decoded[0].1,
        Some(Telemetry::Mag {
            field_ut: [21.6, _, _],
            ..
        })
    ));
}

/// The other way: each MAVLink 2 message, encoded again by the `mavlink` crate with the header pymavlink gave it, is
/// the same bytes — what magcal will send (`PARAM_SET`, stream requests) is what another implementation sends. The
/// MAVLink 1 frame is not: pymavlink 2.4.50 puts `RAW_IMU`'s extension fields (`id`, `temperature`) into it, 29
/// bytes, where the protocol and the crate send the 26 of MAVLink 1 (the crate reads both).
#[test]
fn the_same_messages_encode_to_pymavlink_bytes() {
    let bytes = std::fs::read(fixture("telemetry.bin")).unwrap();
    let mut reader = mavlink::MavlinkReader::new(&bytes[..]);
    let mut at = 0;
    while at < bytes.len() {
        let (version, length) = match bytes[at] {
            0xFD => (mavlink::MavlinkVersion::V2, 12 + usize::from(bytes[at + 1])),
            0xFE => (mavlink::MavlinkVersion::V1, 8 + usize::from(bytes[at + 1])),
            other => panic!("frame start {other:#x} at {at}"),
        };
        let (header, msg) = reader
            .read_any_message::<mavlink::dialects::common::MavMessage>()
            .unwrap();
        let mut again = Vec::new();
        mavlink::write_versioned_msg(&mut again, version, header, &msg).unwrap();
        if version == mavlink::MavlinkVersion::V2 {
            assert_eq!(again, &bytes[at..at + length], "{}", msg.message_name());
        } else {
            assert_eq!((again.len(), length), (26 + 8, 29 + 8), "MAVLink 1 RAW_IMU");
            assert_eq!(
                again[6..32],
                bytes[at + 6..at + 32],
                "the MAVLink 1 fields themselves"
            );
        }
        at += length;
    }
}
