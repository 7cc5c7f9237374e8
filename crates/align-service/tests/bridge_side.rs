//! The service addresses the bridge as the bridge names itself: the thesis's "ros" for a UR
//! bridge, "IiwaDrive" for an iiwa bridge, learnt from the bridge's status reply. A stand-in
//! bridge (a REP socket answering as robot-bridge would) records what the service sends.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::sync::mpsc;

use align_service::server::{Config, start};
use protocol::{Command, RobotSide, StatusBody};

fn example_session() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/step_block_ur10/session.json")
}

fn socket(context: &zmq::Context, kind: zmq::SocketType) -> zmq::Socket {
    let socket = context.socket(kind).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.set_sndtimeo(10_000).unwrap();
    socket
}

/// Answers `requests` instructions as a bridge of `side` would and sends each one's `to` and
/// command on `seen`.
fn stand_in_bridge(
    rep: zmq::Socket,
    side: RobotSide,
    requests: usize,
    seen: mpsc::Sender<(String, Command)>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        for _ in 0..requests {
            let bytes = rep.recv_bytes(0).unwrap();
            let request = protocol::parse_request(&bytes).unwrap();
            let reply = match request.command {
                Command::Status => protocol::to_json(&protocol::status(
                    side,
                    StatusBody {
                        backend: "stand-in".to_owned(),
                        controller: "connected".to_owned(),
                        mirroring: false,
                        sample_rate_hz: 0.0,
                        last_sample_age_s: None,
                        published: 0,
                        reconnects: 0,
                        reason: None,
                        controller_samples_missed: None,
                        session_state: None,
                        connection_quality: None,
                        rejected_datagrams: None,
                        kinematics: None,
                    },
                )),
                _ => protocol::to_json(&protocol::ack_ok(side)),
            };
            rep.send(reply.unwrap().as_bytes(), 0).unwrap();
            seen.send((request.to, request.command)).unwrap();
        }
    })
}

fn mirror_through(side: RobotSide) -> Vec<(String, Command)> {
    let context = zmq::Context::new();
    let rep = socket(&context, zmq::REP);
    rep.bind("tcp://127.0.0.1:*").unwrap();
    let bridge_rep = rep.get_last_endpoint().unwrap().unwrap();
    let publisher = socket(&context, zmq::PUB);
    publisher.bind("tcp://127.0.0.1:*").unwrap();
    let bridge_pub = publisher.get_last_endpoint().unwrap().unwrap();
    let (seen, received) = mpsc::channel();
    // status (to learn the side), start, status (the controller's kinematics), stop.
    let bridge = stand_in_bridge(rep, side, 4, seen);
    let journal = std::env::temp_dir().join(format!(
        "cobot-align-bridge-side-{}-{}.journal",
        side.name(),
        std::process::id()
    ));
    let _ = std::fs::remove_file(&journal);
    let service = start(&Config {
        session: example_session(),
        journal: journal.clone(),
        rep: "tcp://127.0.0.1:*".to_owned(),
        bridge_rep,
        bridge_pub,
        max_sample_age_s: 0.1,
        max_tool_speed_m_s: 0.005,
        data_dirs: Vec::new(),
        keep_session_inspections: true,
        trigger: None,
    })
    .unwrap();
    let client = socket(&context, zmq::REQ);
    client.connect(&service.rep_endpoint).unwrap();
    for command in [
        protocol::ServiceCommand::Start,
        protocol::ServiceCommand::Stop,
    ] {
        let starts = command == protocol::ServiceCommand::Start;
        let request = protocol::to_json(&protocol::service_request(command)).unwrap();
        client.send(request.as_bytes(), 0).unwrap();
        let reply: protocol::ServiceReply =
            serde_json::from_slice(&client.recv_bytes(0).unwrap()).unwrap();
        let mirroring: protocol::MirroringReply = reply.body.into_data("start/stop").unwrap();
        assert_eq!(mirroring.mirroring, starts);
    }
    bridge.join().unwrap();
    service.stop();
    let _ = std::fs::remove_file(&journal);
    received.try_iter().collect()
}

#[test]
fn an_iiwa_bridge_is_addressed_as_iiwa_drive() {
    let seen = mirror_through(RobotSide::IiwaDrive);
    assert_eq!(seen.len(), 4, "{seen:?}");
    assert_eq!(seen[0].1, Command::Status);
    assert_eq!(
        seen[1..],
        [
            ("IiwaDrive".to_owned(), Command::Start),
            ("IiwaDrive".to_owned(), Command::Status),
            ("IiwaDrive".to_owned(), Command::Stop)
        ]
    );
}

#[test]
fn a_ur_bridge_is_addressed_as_ros_as_in_the_thesis() {
    let seen = mirror_through(RobotSide::Ros);
    assert_eq!(
        seen[1..],
        [
            ("ros".to_owned(), Command::Start),
            ("ros".to_owned(), Command::Status),
            ("ros".to_owned(), Command::Stop)
        ]
    );
}

#[test]
fn nonsense_limits_are_refused_before_the_service_starts() {
    for (age_s, speed_m_s) in [(f64::NAN, 0.005), (0.1, -1.0), (f64::INFINITY, 0.005)] {
        let error = start(&Config {
            session: example_session(),
            journal: std::env::temp_dir().join("cobot-align-never-written.journal"),
            rep: "tcp://127.0.0.1:*".to_owned(),
            bridge_rep: "tcp://127.0.0.1:1".to_owned(),
            bridge_pub: "tcp://127.0.0.1:1".to_owned(),
            max_sample_age_s: age_s,
            max_tool_speed_m_s: speed_m_s,
            data_dirs: Vec::new(),
            keep_session_inspections: true,
            trigger: None,
        })
        .unwrap_err();
        assert!(
            error.to_string().contains("must be a positive number"),
            "{error}"
        );
    }
}
