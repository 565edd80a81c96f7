//! The serial protocol (`ribreg_core::wire`) against golden byte vectors from an
//! independent implementation.
//!
//! `tests/fixtures/golden/wire.json` is written by `tests/golden/gen_wire.py`, a Python
//! script of the standard library only (its own postcard encoder, CRC-16/CCITT-FALSE and
//! COBS, written from the specifications; no postcard package). Regenerate it from the
//! repository root with Python 3.11 (the checked-in file was made with Python 3.11.7,
//! recorded in the file under `"generator"`):
//!
//! ```text
//! python3 tests/golden/gen_wire.py
//! ```
//!
//! Per case, the message is given in serde's externally tagged JSON form and rebuilt here
//! with `serde_json`; `wire::encode` must give exactly the frame bytes, the envelope's
//! postcard bytes and its CRC must match, and `wire::decode` of the fixture's frame must
//! give back the same sequence number and message.

use ribreg_core::wire::{
    self, Command, Fault, FrameError, FromController, NackCode, Receiver, State, ToController,
    MAX_FRAME,
};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeSet;
use std::fmt::Debug;

fn fixture() -> Value {
    let path = format!("{}/fixtures/golden/wire.json", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn unhex(s: &str) -> Vec<u8> {
    assert!(s.len() % 2 == 0, "odd hex length");
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn uint(v: &Value) -> u64 {
    v.as_u64()
        .unwrap_or_else(|| panic!("not an unsigned integer: {v}"))
}

/// Every frame `bytes` completes in `rx`, copied out.
fn frames(rx: &mut Receiver, bytes: &[u8]) -> Vec<Result<Vec<u8>, FrameError>> {
    bytes
        .iter()
        .filter_map(|&b| rx.push(b).map(|r| r.map(|f| f.to_vec())))
        .collect()
}

// The variant names; the exhaustive matches make a new variant a compile error here, and
// `golden_vectors_cover_every_variant` then asks for a golden case of it.
const TO_CONTROLLER: [&str; 8] = [
    "Hello",
    "Configure",
    "TemplateNodes",
    "TemplateShape",
    "Waypoints",
    "Pose",
    "Frame",
    "Command",
];
const FROM_CONTROLLER: [&str; 7] = [
    "HelloAck", "Ack", "Nack", "Status", "Waypoint", "Setpoint", "Fault",
];
const COMMANDS: [Command; 7] = [
    Command::StartSweep,
    Command::EndSweep,
    Command::Register,
    Command::Execute,
    Command::Abort,
    Command::Status,
    Command::Result,
];
const STATES: [State; 7] = [
    State::Idle,
    State::TemplateLoaded,
    State::Sweeping,
    State::Registering,
    State::Ready,
    State::Executing,
    State::Done,
];
const NACK_CODES: [&str; 6] = [
    "Corrupt",
    "OutOfOrder",
    "TooLong",
    "Version",
    "BadState",
    "Invalid",
];
const FAULTS: [&str; 2] = ["PoseTimeout", "Registration"];

/// Variant names of a message and of the enums inside it.
fn to_variants(m: &ToController, seen: &mut BTreeSet<String>) {
    let name = match m {
        ToController::Hello { .. } => "Hello",
        ToController::Configure(_) => "Configure",
        ToController::TemplateNodes { .. } => "TemplateNodes",
        ToController::TemplateShape(_) => "TemplateShape",
        ToController::Waypoints { .. } => "Waypoints",
        ToController::Pose(_) => "Pose",
        ToController::Frame(_) => "Frame",
        ToController::Command(c) => {
            seen.insert(format!("Command::{c:?}"));
            "Command"
        }
    };
    seen.insert(format!("ToController::{name}"));
}

fn from_variants(m: &FromController, seen: &mut BTreeSet<String>) {
    let name = match m {
        FromController::HelloAck { .. } => "HelloAck",
        FromController::Ack { .. } => "Ack",
        FromController::Nack { code, .. } => {
            seen.insert(format!(
                "NackCode::{}",
                match code {
                    NackCode::Corrupt => "Corrupt",
                    NackCode::OutOfOrder => "OutOfOrder",
                    NackCode::TooLong => "TooLong",
                    NackCode::Version => "Version",
                    NackCode::BadState => "BadState",
                    NackCode::Invalid(_) => "Invalid",
                }
            ));
            "Nack"
        }
        FromController::Status(s) => {
            seen.insert(format!("State::{:?}", s.state));
            "Status"
        }
        FromController::Waypoint(_) => "Waypoint",
        FromController::Setpoint(_) => "Setpoint",
        FromController::Fault(f) => {
            seen.insert(format!(
                "Fault::{}",
                match f {
                    Fault::PoseTimeout => "PoseTimeout",
                    Fault::Registration(_) => "Registration",
                }
            ));
            "Fault"
        }
    };
    seen.insert(format!("FromController::{name}"));
}

/// Checks one golden case of message type `T`; returns the rebuilt message.
fn check_case<T>(case: &Value) -> T
where
    T: Serialize + DeserializeOwned + PartialEq + Debug,
{
    let name = case["name"].as_str().expect("name");
    let seq = u16::try_from(uint(&case["seq"])).expect("seq is a u16");
    let msg: T = serde_json::from_value(case["message"].clone())
        .unwrap_or_else(|e| panic!("{name}: message does not build: {e}"));
    let want_postcard = unhex(case["postcard"].as_str().expect("postcard"));
    let want_frame = unhex(case["frame"].as_str().expect("frame"));
    assert_eq!(
        uint(&case["frame_len"]) as usize,
        want_frame.len(),
        "{name}"
    );

    // The envelope's postcard bytes (a `(u16, T)` tuple encodes as `Envelope { seq, msg }`).
    let mut buf = [0u8; 2 * MAX_FRAME];
    let post = postcard::to_slice(&(seq, &msg), &mut buf).expect("postcard");
    assert_eq!(hex(post), hex(&want_postcard), "{name}: postcard bytes");
    assert_eq!(
        u64::from(wire::crc16(post)),
        uint(&case["crc"]),
        "{name}: CRC"
    );

    // encode → exactly the frame.
    let mut out = [0u8; MAX_FRAME];
    let n = wire::encode(seq, &msg, &mut out).unwrap_or_else(|e| panic!("{name}: encode: {e}"));
    assert_eq!(hex(&out[..n]), hex(&want_frame), "{name}: frame bytes");
    assert!(n <= MAX_FRAME, "{name}: {n} bytes");

    // The fixture's frame through the receiver and decode → the same (seq, message).
    let mut rx = Receiver::new();
    let got = frames(&mut rx, &want_frame);
    assert_eq!(got.len(), 1, "{name}: one frame, at the delimiter");
    let mut body = got.into_iter().next().unwrap().expect("frame");
    assert_eq!(body.len() + 1, want_frame.len(), "{name}");
    let (s, back) = wire::decode::<T>(&mut body).unwrap_or_else(|e| panic!("{name}: decode: {e}"));
    assert_eq!(s, seq, "{name}: seq");
    assert_eq!(back, msg, "{name}: message");
    // PartialEq takes -0.0 for 0.0: the bits must survive too.
    let mut again = [0u8; MAX_FRAME];
    let m = wire::encode(s, &back, &mut again).unwrap();
    assert_eq!(hex(&again[..m]), hex(&want_frame), "{name}: re-encoded");
    msg
}

#[test]
fn golden_constants() {
    let v = fixture();
    let c = &v["constants"];
    let gen = &v["generator"];
    assert_eq!(gen["script"], "tests/golden/gen_wire.py");
    assert!(
        gen["python"].as_str().expect("python").starts_with("3.11."),
        "fixture made with Python {}; the script pins 3.11",
        gen["python"]
    );
    assert_eq!(uint(&c["magic"]), u64::from(wire::MAGIC));
    assert_eq!(wire::MAGIC, 0x4752_4252);
    assert_eq!(uint(&c["version"]), u64::from(wire::VERSION));
    assert_eq!(uint(&c["crc_check_123456789"]), 0x29B1);
    assert_eq!(wire::crc16(b"123456789"), 0x29B1);
    // The maxima the script derives from its own schemas and reaches with actual messages.
    assert_eq!(
        uint(&c["max_to_controller"]) as usize,
        wire::MAX_TO_CONTROLLER
    );
    assert_eq!(
        uint(&c["max_from_controller"]) as usize,
        wire::MAX_FROM_CONTROLLER
    );
    assert_eq!(uint(&c["max_frame"]) as usize, MAX_FRAME);
}

#[test]
fn golden_vectors() {
    let v = fixture();
    let cases = v["cases"].as_array().expect("cases");
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let mut seen = BTreeSet::new();
    let mut seqs = BTreeSet::new();
    for case in cases {
        seqs.insert(uint(&case["seq"]));
        match case["direction"].as_str().expect("direction") {
            "to_controller" => to_variants(&check_case::<ToController>(case), &mut seen),
            "from_controller" => from_variants(&check_case::<FromController>(case), &mut seen),
            d => panic!("unknown direction {d}"),
        }
    }
    // Every variant of every enum of the protocol has a golden case.
    let mut want = BTreeSet::new();
    want.extend(TO_CONTROLLER.iter().map(|n| format!("ToController::{n}")));
    want.extend(
        FROM_CONTROLLER
            .iter()
            .map(|n| format!("FromController::{n}")),
    );
    want.extend(COMMANDS.iter().map(|c| format!("Command::{c:?}")));
    want.extend(STATES.iter().map(|s| format!("State::{s:?}")));
    want.extend(NACK_CODES.iter().map(|n| format!("NackCode::{n}")));
    want.extend(FAULTS.iter().map(|n| format!("Fault::{n}")));
    let missing: Vec<_> = want.difference(&seen).collect();
    assert!(missing.is_empty(), "no golden case for {missing:?}");
    // The varint boundaries of the sequence number.
    for s in [0, 1, 0x7F, 0x80, 0x3FFF, 0x4000, 0xFFFF] {
        assert!(seqs.contains(&s), "no golden case with seq {s:#x}");
    }
}
