//! The control socket against the malformed input an independent fault test sent: a request in
//! two frames, raw TCP bytes that are not ZMTP, arrays where objects belong and oversized
//! requests. Each gets a reason or is dropped by libzmq, and the socket answers the next
//! well-formed request.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::io::Write;
use std::net::{Shutdown, TcpStream};
use std::time::Duration;

use align_core::robots::ShippedRobot;

/// How long a client waits for any reply before the test fails.
const REPLY_TIMEOUT_MS: i32 = 5000;

fn start_simulator() -> sim_robot::SimHandle {
    sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: None,
        calibration: None,
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap()
}

fn client(context: &zmq::Context, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(REPLY_TIMEOUT_MS).unwrap();
    socket.set_sndtimeo(REPLY_TIMEOUT_MS).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

/// Sends `frames` as one message and returns the reply as JSON.
fn request(socket: &zmq::Socket, frames: &[&[u8]]) -> serde_json::Value {
    socket.send_multipart(frames, 0).unwrap();
    let reply = socket.recv_bytes(0).expect("a reply within the timeout");
    serde_json::from_slice(&reply).unwrap()
}

/// The reason of a refusal, failing the test if the request was not refused.
fn refusal(reply: &serde_json::Value) -> String {
    assert_eq!(reply["ok"], false, "{reply}");
    reply["reason"].as_str().unwrap().to_owned()
}

/// A fresh client's `status` is answered: the control socket still serves.
fn assert_status_answered(context: &zmq::Context, endpoint: &str) {
    let socket = client(context, endpoint);
    let reply = request(&socket, &[br#"{"command":"status"}"#]);
    assert_eq!(reply["ok"], true, "{reply}");
}

fn control_port(endpoint: &str) -> u16 {
    endpoint.rsplit(':').next().unwrap().parse().unwrap()
}

/// Deterministic bytes that look random (xorshift64), so a failure can be replayed.
fn garbage(seed: u64, length: usize) -> Vec<u8> {
    let mut state = seed.max(1);
    (0..length)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state.to_le_bytes()[0]
        })
        .collect()
}

#[test]
fn a_two_frame_request_is_refused_and_the_socket_keeps_serving() {
    let simulator = start_simulator();
    let context = zmq::Context::new();
    let socket = client(&context, &simulator.control_endpoint);
    let reply = request(&socket, &[br#"{"command":"status"}"#, b"junk"]);
    let reason = refusal(&reply);
    assert!(reason.contains("multipart"), "{reason}");
    assert!(reason.contains("2 frames"), "{reason}");
    // The same client, then a new one.
    let reply = request(&socket, &[br#"{"command":"status"}"#]);
    assert_eq!(reply["ok"], true, "{reply}");
    assert_status_answered(&context, &simulator.control_endpoint);
    simulator.stop();
}

#[test]
fn raw_tcp_garbage_leaves_the_control_socket_serving() {
    let simulator = start_simulator();
    let context = zmq::Context::new();
    let port = control_port(&simulator.control_endpoint);
    // A ZMTP 3 signature followed by garbage reaches further into libzmq's handshake than
    // garbage alone.
    let zmtp_signature: &[u8] = &[0xff, 0, 0, 0, 0, 0, 0, 0, 1, 0x7f];
    for seed in 1..=8_u64 {
        let mut bytes = if seed % 2 == 0 {
            zmtp_signature.to_vec()
        } else {
            Vec::new()
        };
        bytes.extend(garbage(seed, 4096));
        let mut stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
        stream
            .set_write_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        // libzmq may close the connection part way through: what was written is enough.
        let _ = stream.write_all(&bytes);
        // While the garbage peer is still connected, and after it has gone.
        assert_status_answered(&context, &simulator.control_endpoint);
        let _ = stream.shutdown(Shutdown::Both);
        drop(stream);
        assert_status_answered(&context, &simulator.control_endpoint);
    }
    simulator.stop();
}

#[test]
fn arrays_in_place_of_objects_are_refused_with_a_reason() {
    let simulator = start_simulator();
    let context = zmq::Context::new();
    let socket = client(&context, &simulator.control_endpoint);
    let cases: [(&str, &str); 6] = [
        (r#"[["status"]]"#, "must be a JSON object, got an array"),
        (r#"["status"]"#, "must be a JSON object, got an array"),
        (r#"{"command":["status"]}"#, "'command' must be a string"),
        (
            r#"{"command":"motion","motion":["hold",[0,0,0,0,0,0]]}"#,
            "'motion' must be an object, got an array",
        ),
        (
            r#"{"command":"motion","motion":{"kind":"path","waypoints":[[0.0,[0,0,0,0,0,0]]]}}"#,
            "'motion.waypoints[0]' must be an object, got an array",
        ),
        (
            r#"{"command":"effects","payload":[1.0,[0,0,0]]}"#,
            "'payload' must be an object, got an array",
        ),
    ];
    for (text, expected) in cases {
        let reason = refusal(&request(&socket, &[text.as_bytes()]));
        assert!(reason.contains(expected), "{text}: {reason}");
    }
    let reply = request(&socket, &[br#"{"command":"status"}"#]);
    assert_eq!(reply["ok"], true, "{reply}");
    simulator.stop();
}

#[test]
fn oversized_requests_are_refused_with_a_reason() {
    let simulator = start_simulator();
    let context = zmq::Context::new();
    let socket = client(&context, &simulator.control_endpoint);
    // Valid JSON padded with white space: refused for its size, not its content.
    let mut oversized = br#"{"command":"status"}"#.to_vec();
    oversized.resize(sim_robot::MAX_REQUEST_BYTES + 1, b' ');
    let reason = refusal(&request(&socket, &[&oversized]));
    assert!(reason.contains("exceeds the 65536-byte limit"), "{reason}");
    // Many small frames that add up past the limit: refused as multipart, and drained.
    let frame = vec![b' '; 1024];
    let frames: Vec<&[u8]> = (0..100).map(|_| frame.as_slice()).collect();
    let reason = refusal(&request(&socket, &frames));
    assert!(reason.contains("100 frames"), "{reason}");
    let reply = request(&socket, &[br#"{"command":"status"}"#]);
    assert_eq!(reply["ok"], true, "{reply}");
    simulator.stop();
}
