//! The contract: the thesis's exact texts parse, our acks are the thesis's bytes, every golden
//! file round-trips through the Rust types and validates against its schema, and malformed
//! requests are refused with a reason.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};

use protocol::{
    Command, HwState, Instruction, ProtocolError, RobotSide, Status, ack_error, ack_ok,
    instruction, parse_request, to_json,
};

const THESIS_START: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"start","content":"hwState"}}"#;
const THESIS_STOP: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"stop","content":"hwState"}}"#;
const THESIS_OK: &str = r#"{"header":{"from":"ros","to":"ips","type":"instruction"},"body":{"command":"ack","content":"ok"}}"#;
const THESIS_ERROR: &str = r#"{"header":{"from":"ros","to":"ips","type":"instruction"},"body":{"command":"ack","content":"error"}}"#;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_owned()
}

fn schema(name: &str) -> jsonschema::Validator {
    let text = std::fs::read_to_string(root().join("schemas").join(name)).unwrap();
    jsonschema::validator_for(&serde_json::from_str(&text).unwrap()).unwrap()
}

#[test]
fn thesis_requests_parse() {
    assert_eq!(
        parse_request(THESIS_START.as_bytes()).unwrap().command,
        Command::Start
    );
    assert_eq!(
        parse_request(THESIS_STOP.as_bytes()).unwrap().command,
        Command::Stop
    );
    // With spaces and fields in another order, as other JSON writers produce.
    let reordered = r#"{ "body": {"content": "hwState", "command": "start"}, "header": {"type": "instruction", "to": "IiwaDrive", "from": "ips"} }"#;
    let request = parse_request(reordered.as_bytes()).unwrap();
    assert_eq!(
        (request.command, request.to.as_str()),
        (Command::Start, "IiwaDrive")
    );
}

#[test]
fn our_messages_are_the_thesis_bytes() {
    assert_eq!(
        to_json(&instruction(RobotSide::Ros, Command::Start)).unwrap(),
        THESIS_START
    );
    assert_eq!(
        to_json(&instruction(RobotSide::Ros, Command::Stop)).unwrap(),
        THESIS_STOP
    );
    assert_eq!(to_json(&ack_ok(RobotSide::Ros)).unwrap(), THESIS_OK);
    // The error ack is the thesis's with one extra field, which thesis clients ignore.
    let error = to_json(&ack_error(RobotSide::Ros, "controller not connected")).unwrap();
    assert_eq!(
        error,
        THESIS_ERROR.replace(
            r#""error"}}"#,
            r#""error","reason":"controller not connected"}}"#
        )
    );
    let iiwa = to_json(&ack_ok(RobotSide::IiwaDrive)).unwrap();
    assert_eq!(iiwa, THESIS_OK.replace("\"ros\"", "\"IiwaDrive\""));
}

#[test]
fn golden_files_round_trip_and_validate_against_their_schemas() {
    let instruction_schema = schema("instruction.schema.json");
    let hw_state_schema = schema("hw_state.schema.json");
    let status_schema = schema("status.schema.json");
    let service_schema = schema("service.schema.json");
    let mut checked = 0;
    for entry in std::fs::read_dir(root().join("examples")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        let (validator, round_trip) = match value["header"]["type"].as_str().unwrap() {
            "instruction" => (
                &instruction_schema,
                to_json(&serde_json::from_str::<Instruction>(&text).unwrap()).unwrap(),
            ),
            "hwState" => (
                &hw_state_schema,
                to_json(&serde_json::from_str::<HwState>(&text).unwrap()).unwrap(),
            ),
            "status" => (
                &status_schema,
                to_json(&serde_json::from_str::<Status>(&text).unwrap()).unwrap(),
            ),
            "request" => (
                &service_schema,
                to_json(&serde_json::from_str::<protocol::ServiceRequest>(&text).unwrap()).unwrap(),
            ),
            "reply" => (
                &service_schema,
                to_json(&serde_json::from_str::<protocol::ServiceReply>(&text).unwrap()).unwrap(),
            ),
            other => panic!("{name}: unknown type {other}"),
        };
        let errors: Vec<String> = validator
            .iter_errors(&value)
            .map(|e| e.to_string())
            .collect();
        assert!(errors.is_empty(), "{name}: {errors:?}");
        // Byte for byte: the golden files are written exactly as our serialiser writes them.
        assert_eq!(round_trip, text.trim_end(), "{name}");
        checked += 1;
    }
    assert!(checked >= 8, "only {checked} golden files");
}

#[test]
fn schemas_reject_what_receivers_would_choke_on() {
    let hw_state_schema = schema("hw_state.schema.json");
    let bad = serde_json::json!({"header": {"from": "ros", "to": "ips", "type": "hwState"}, "body": {"names": ["a"], "position": ["x"], "velocity": [0.0], "seq": 1, "stamp": 1.0, "controller_time": 1.0}});
    assert!(!hw_state_schema.is_valid(&bad));
    let instruction_schema = schema("instruction.schema.json");
    let bad_ack = serde_json::json!({"header": {"from": "ros", "to": "ips", "type": "instruction"}, "body": {"command": "ack", "content": "maybe"}});
    assert!(!instruction_schema.is_valid(&bad_ack));
}

#[test]
fn unknown_fields_are_ignored() {
    let text = r#"{"header":{"from":"ips","to":"ros","type":"instruction","client":"ips-2024"},"body":{"command":"stop","content":"hwState","priority":3}}"#;
    assert_eq!(
        parse_request(text.as_bytes()).unwrap().command,
        Command::Stop
    );
}

#[test]
fn malformed_requests_are_refused_with_the_reason() {
    let reason = |bytes: &[u8]| parse_request(bytes).unwrap_err().to_string();
    assert!(reason(b"{not json").starts_with("the message is not valid JSON"));
    assert!(reason(&[0xff, 0x00, 0x13]).starts_with("the message is not valid JSON"));
    assert!(
        reason(br#"{"header":{"from":"ips"}}"#)
            .starts_with("the message does not have the expected shape")
    );
    assert!(reason(br#"[1,2,3]"#).starts_with("the message does not have the expected shape"));
    assert_eq!(
        reason(br#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"jump","content":"hwState"}}"#),
        "unknown command 'jump' (expected start, stop or status)"
    );
    assert_eq!(
        reason(br#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"start","content":"video"}}"#),
        "unknown content 'video' (expected 'hwState')"
    );
    assert_eq!(
        reason(br#"{"header":{"from":"ips","to":"ros","type":"hwState"},"body":{"command":"start","content":"hwState"}}"#),
        "unknown message type 'hwState' (expected 'instruction')"
    );
}

#[test]
fn senders_never_emit_nan() {
    let text = std::fs::read_to_string(root().join("examples/hw_state_ur.json")).unwrap();
    let mut message: HwState = serde_json::from_str(&text).unwrap();
    message.body.position[2] = f64::NAN;
    assert_eq!(
        to_json(&message).unwrap_err(),
        ProtocolError::NonFinite(".body.position[2]".to_owned())
    );
    message.body.position[2] = 0.0;
    message.body.velocity.pop();
    assert!(matches!(
        to_json(&message).unwrap_err(),
        ProtocolError::Shape(_)
    ));
}

#[test]
fn service_requests_never_carry_nan_and_align_cloud_needs_a_cloud() {
    let with_delta = |delta_m: f64, start_pose: Option<protocol::Pose>| {
        protocol::service_request(protocol::ServiceCommand::AlignCloud(Box::new(
            protocol::AlignCloudRequest {
                cloud: "scan.ply".to_owned(),
                delta_m: Some(delta_m),
                start_pose,
                ..Default::default()
            },
        )))
    };
    assert_eq!(
        to_json(&with_delta(f64::NAN, None)).unwrap_err(),
        ProtocolError::NonFinite(".body.delta_m".to_owned())
    );
    let infinite = protocol::Pose::new([0.6, f64::INFINITY, 0.0], [0.0; 3]);
    assert_eq!(
        to_json(&with_delta(0.1, Some(infinite))).unwrap_err(),
        ProtocolError::NonFinite(".body.start_pose.xyz[1]".to_owned())
    );
    let service_schema = schema("service.schema.json");
    let without_cloud = serde_json::json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": {"command": "align-cloud", "delta_m": 0.1}});
    assert!(!service_schema.is_valid(&without_cloud));
    let negative_delta = serde_json::json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": {"command": "align-cloud", "cloud": "scan.ply", "delta_m": -0.1}});
    assert!(!service_schema.is_valid(&negative_delta));
}

#[test]
fn arrays_in_place_of_objects_are_refused() {
    let bridge = parse_request(br#"[["ips","ros","instruction"],["stop","hwState"]]"#);
    assert_eq!(
        bridge.unwrap_err().to_string(),
        "the message does not have the expected shape: expected a JSON object, got an array"
    );
    let header_array = parse_request(
        br#"{"header":["ips","ros","instruction"],"body":{"command":"stop","content":"hwState"}}"#,
    );
    assert_eq!(
        header_array.unwrap_err().to_string(),
        "the message does not have the expected shape: 'header' must be an object, got an array"
    );
    let service = protocol::parse_service_request(br#"[["a","b","c"],["reset"]]"#);
    assert!(
        service
            .unwrap_err()
            .to_string()
            .contains("expected a JSON object, got an array")
    );
}

#[test]
fn service_requests_are_typed_by_their_command() {
    let parse = |text: &str| protocol::parse_service_request(text.as_bytes());
    let envelope = |body: &str| {
        format!(r#"{{"header":{{"from":"ips","to":"align","type":"request"}},"body":{body}}}"#)
    };
    assert_eq!(
        parse(&envelope(r#"{"command":"reset"}"#)).unwrap().body,
        protocol::ServiceCommand::Reset
    );
    // Unknown fields are ignored, as everywhere in the protocol.
    assert_eq!(
        parse(&envelope(r#"{"command":"align","extra":1}"#))
            .unwrap()
            .body,
        protocol::ServiceCommand::Align
    );
    assert!(
        parse(&envelope(r#"{"command":"fly"}"#))
            .unwrap_err()
            .to_string()
            .starts_with("unknown command 'fly' (expected status, start")
    );
    assert_eq!(
        parse(&envelope(r#"{"command":"save"}"#))
            .unwrap_err()
            .to_string(),
        "the message does not have the expected shape: save needs a 'path'"
    );
    assert!(
        parse(&envelope(r#"{"command":7}"#))
            .unwrap_err()
            .to_string()
            .contains("body.command must be a string")
    );
    assert!(
        parse(&envelope(r#"{"command":"remove","ids":"3"}"#))
            .unwrap_err()
            .to_string()
            .contains("remove: invalid type")
    );
    assert!(
        parse("{\"header\": NaN}")
            .unwrap_err()
            .to_string()
            .contains("NaN and Infinity are not JSON numbers")
    );
    let huge = envelope(&format!(
        r#"{{"command":"list","pad":"{}"}}"#,
        "x".repeat(70_000)
    ));
    assert!(
        parse(&huge)
            .unwrap_err()
            .to_string()
            .contains("exceeds the 65536-byte limit")
    );
    for name in [
        "service_get.json",
        "service_get_at.json",
        "service_remove.json",
        "service_align_cloud.json",
        "service_diagnose.json",
    ] {
        let text = std::fs::read_to_string(root().join("examples").join(name)).unwrap();
        let request = parse(&text).unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!(to_json(&request).unwrap(), text.trim_end(), "{name}");
    }
}

#[test]
fn golden_replies_read_as_their_typed_documents() {
    let reply = |name: &str| -> protocol::ServiceReply {
        let text = std::fs::read_to_string(root().join("examples").join(name)).unwrap();
        serde_json::from_str(&text).unwrap()
    };
    let diagnosis: protocol::reports::DiagnoseReport = reply("service_reply_diagnose.json")
        .body
        .into_data("diagnose")
        .unwrap();
    assert_eq!(diagnosis.verdict, "effect");
    assert_eq!(diagnosis.effect.as_ref().unwrap().name, "probe_radius");
    let cloud: protocol::reports::CloudReport = reply("service_reply_align_cloud.json")
        .body
        .into_data("align-cloud")
        .unwrap();
    assert!(cloud.alignment.pose.matrix.is_some());
    let inspection: protocol::Inspection = reply("service_reply_get.json")
        .body
        .into_data("get")
        .unwrap();
    assert_eq!(inspection.id, "5");
    let refused = reply("service_reply_stale.json")
        .body
        .into_data::<protocol::Inspection>("get");
    assert!(
        matches!(refused, Err(protocol::ReplyError::Refused(reason)) if reason.starts_with("latest joint state"))
    );
    // A typed document re-serialised through the reply is the golden file's bytes.
    let text =
        std::fs::read_to_string(root().join("examples/service_reply_diagnose.json")).unwrap();
    assert_eq!(
        to_json(&protocol::service_reply_ok(&diagnosis).unwrap()).unwrap(),
        text.trim_end()
    );
}
