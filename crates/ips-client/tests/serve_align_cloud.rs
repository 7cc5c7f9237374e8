//! The service's `align-cloud` request over a real socket: the shipped example scan aligned from
//! the session part's nominal pose gives the truth and the document of `ips align-cloud --json`;
//! the client command `ips align-cloud --service` prints it; bad requests are refused with a
//! reason each, and the service keeps answering.
//!
//! No robot is needed: the service's bridge endpoints are sockets this test binds and never
//! uses.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use align_service::server::{Config as ServeConfig, Handle as ServeHandle};
use serde_json::{Value, json};

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn example_str(file: &str) -> String {
    example(file).to_str().unwrap().to_owned()
}

fn socket(context: &zmq::Context, kind: zmq::SocketType) -> zmq::Socket {
    let socket = context.socket(kind).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(20_000).unwrap();
    socket
}

/// The service on the example session (paths made absolute), with stand-ins for the bridge.
struct Fixture {
    service: ServeHandle,
    folder: PathBuf,
    // Bound so the service's bridge endpoints exist; the test never asks for mirroring.
    _bridge_rep: zmq::Socket,
    _bridge_pub: zmq::Socket,
    client: zmq::Socket,
    _context: zmq::Context,
}

impl Fixture {
    fn start(name: &str) -> Self {
        let context = zmq::Context::new();
        let bridge_rep = socket(&context, zmq::REP);
        bridge_rep.bind("tcp://127.0.0.1:*").unwrap();
        let bridge_pub = socket(&context, zmq::PUB);
        bridge_pub.bind("tcp://127.0.0.1:*").unwrap();
        let endpoint = |s: &zmq::Socket| s.get_last_endpoint().unwrap().unwrap();
        let mut session: Value =
            serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap())
                .unwrap();
        session["robot"]["urdf"] = json!(example_str("../../robots/ur10.urdf"));
        session["part"]["mesh"] = json!(example_str("step_block.stl"));
        let folder = std::env::temp_dir().join(format!(
            "cobot-align-serve-cloud-{name}-{}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&folder);
        std::fs::create_dir_all(&folder).unwrap();
        std::fs::write(folder.join("session.json"), session.to_string()).unwrap();
        let service = align_service::server::start(&ServeConfig {
            session: folder.join("session.json"),
            journal: folder.join("inspections.journal"),
            rep: "tcp://127.0.0.1:*".to_owned(),
            bridge_rep: endpoint(&bridge_rep),
            bridge_pub: endpoint(&bridge_pub),
            max_sample_age_s: 0.1,
            max_tool_speed_m_s: 0.005,
            data_dirs: vec![folder.clone(), example("")],
            keep_session_inspections: true,
            trigger: None,
        })
        .unwrap();
        let client = socket(&context, zmq::REQ);
        client.connect(&service.rep_endpoint).unwrap();
        Self {
            service,
            folder,
            _bridge_rep: bridge_rep,
            _bridge_pub: bridge_pub,
            client,
            _context: context,
        }
    }

    /// Sends raw request text (so tests can send what no typed client would) and returns the
    /// reply's body.
    fn send_text(&self, text: &str) -> Value {
        self.client.send(text.as_bytes(), 0).unwrap();
        let reply: Value = serde_json::from_slice(&self.client.recv_bytes(0).unwrap()).unwrap();
        assert_eq!(reply["header"]["type"], "reply", "{reply}");
        reply["body"].clone()
    }

    fn call(&self, body: Value) -> Value {
        self.send_text(
            &json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body})
                .to_string(),
        )
    }

    fn finish(self) {
        self.service.stop();
        let _ = std::fs::remove_dir_all(&self.folder);
    }
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

fn json_stdout(output: &Output) -> Value {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

/// Position error (m) and yaw error (rad) of an align-cloud document against truth.json.
fn error_against_truth(result: &Value) -> (f64, f64) {
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(example("truth.json")).unwrap()).unwrap();
    let translation = (0..3)
        .map(|i| {
            result["pose"]["xyz"][i].as_f64().unwrap()
                - truth["base_from_part"]["xyz"][i].as_f64().unwrap()
        })
        .map(|d| d * d)
        .sum::<f64>()
        .sqrt();
    let yaw = (result["pose"]["rpy"][2].as_f64().unwrap()
        - truth["base_from_part"]["rpy"][2].as_f64().unwrap())
    .abs();
    (translation, yaw)
}

fn keys(document: &Value) -> BTreeSet<String> {
    document.as_object().unwrap().keys().cloned().collect()
}

#[test]
fn example_scan_aligned_by_the_service_recovers_the_true_pose() {
    let fixture = Fixture::start("truth");
    let scan = example_str("scan.xyz");
    // Only the cloud and its unit: part, start pose (the nominal one) and delta are defaults.
    let reply =
        fixture.call(json!({"command": "align-cloud", "cloud": scan, "cloud_scale": 0.001}));
    assert_eq!(reply["ok"], true, "{reply}");
    let data = &reply["data"];
    let (translation_m, yaw_rad) = error_against_truth(data);
    // Scan noise 0.3 mm, floor, a neighbour and 10% outliers: well under the 1 mm success bar.
    assert!(translation_m < 2e-4, "{translation_m}");
    assert!(yaw_rad * 0.2 < 2e-4, "{yaw_rad}");
    assert!(data["kept_points"].as_u64().unwrap() > 1000, "{data}");
    // With the pose's uncertainty, the noise measured on the scan.
    assert_eq!(data["uncertainty"]["sigma_source"], "scan", "{data}");
    assert!(data["uncertainty"]["pose_distance_95_mm"].as_f64().unwrap() < 1.0);

    // The offline command with the same inputs: the same document, key for key.
    let offline = json_stdout(&ips(&[
        "align-cloud",
        "--cloud",
        &scan,
        "--cloud-scale",
        "0.001",
        "--mesh",
        &example_str("step_block.stl"),
        "--mesh-scale",
        "0.001",
        "--pose",
        "0.65,-0.22,0.02,0,0,0.25",
        "--delta",
        "0.1",
        "--json",
    ]));
    assert_eq!(keys(data), keys(&offline));
    assert_eq!(data["cloud_points"], offline["cloud_points"]);

    // The client command asks the service and prints the same document.
    let endpoint = fixture.service.rep_endpoint.clone();
    let asked = json_stdout(&ips(&[
        "align-cloud",
        "--service",
        &endpoint,
        "--cloud",
        &scan,
        "--cloud-scale",
        "0.001",
        "--json",
    ]));
    assert_eq!(keys(&asked), keys(&offline));
    let (translation_m, _) = error_against_truth(&asked);
    assert!(translation_m < 2e-4, "{translation_m}");
    // Readable text by default.
    let text = ips(&[
        "align-cloud",
        "--service",
        &endpoint,
        "--cloud",
        &scan,
        "--cloud-scale",
        "0.001",
    ]);
    let text = String::from_utf8(text.stdout).unwrap();
    assert!(text.starts_with("base_from_part: xyz [m] 0.62"), "{text}");
    assert!(text.contains("cloud points ->"), "{text}");
    assert!(text.contains("95% confidence (noise sigma"), "{text}");
    fixture.finish();
}

#[test]
fn ips_align_asks_the_service_to_align_its_inspections() {
    let fixture = Fixture::start("align");
    let endpoint = fixture.service.rep_endpoint.clone();
    // No inspections: refused with the service's reason, exit 2.
    assert_eq!(fixture.call(json!({"command": "reset"}))["ok"], true);
    let empty = ips(&["align", "--service", &endpoint]);
    assert_eq!(empty.status.code(), Some(2));
    // The example session's nine touches, loaded into the service.
    let loaded = fixture.call(json!({"command": "load", "path": example_str("session.json")}));
    assert_eq!(loaded["ok"], true, "{loaded}");
    let offline = json_stdout(&ips(&["align", &example_str("session.json"), "--json"]));
    let asked = json_stdout(&ips(&["align", "--service", &endpoint, "--json"]));
    assert_eq!(keys(&asked), keys(&offline));
    let (translation_m, yaw_rad) = error_against_truth(&asked);
    assert!(translation_m < 1e-6 && yaw_rad < 1e-6, "{asked}");
    let text = String::from_utf8(ips(&["align", "--service", &endpoint]).stdout).unwrap();
    assert!(text.starts_with("base_from_part: xyz [m] 0.62"), "{text}");
    // A capture at a controller time needs joint states, which this robotless service lacks.
    let at = ips(&["get", "--at", "12.5", "--service", &endpoint]);
    assert_eq!(at.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&at.stderr).contains("no joint state received yet"));
    // The service aligns with its defaults: the thesis's switches are refused with --service.
    let refused = ips(&["align", "--service", &endpoint, "--local"]);
    assert_eq!(refused.status.code(), Some(2));
    fixture.finish();
}

#[test]
fn bad_align_cloud_requests_are_refused_with_a_reason_and_the_service_keeps_answering() {
    let fixture = Fixture::start("bad");
    let scan = example_str("scan.xyz");
    let envelope = |body: &str| {
        format!(r#"{{"header":{{"from":"ips","to":"align","type":"request"}},"body":{body}}}"#)
    };
    let cases: Vec<(String, String)> = vec![
        (
            envelope(r#"{"command":"align-cloud"}"#),
            "align-cloud needs a 'cloud'".to_owned(),
        ),
        (
            envelope(r#"{"command":"align-cloud","cloud":"/no/such/scan.xyz"}"#),
            "'/no/such/scan.xyz': No such file".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","cloud_scale":0.001,"delta_m":NaN}}"#
            )),
            "NaN and Infinity are not JSON numbers".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","delta_m":-0.1}}"#
            )),
            "delta_m must be a positive distance in m, got -0.1".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","delta_m":"0.1"}}"#
            )),
            "invalid type: string \"0.1\", expected f64".to_owned(),
        ),
        (
            envelope(r#"{"command":"align-cloud","cloud":42}"#),
            "invalid type: integer `42`, expected a string".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","start_pose":{{"xyz":[0.6,0.1],"rpy":[0,0,0]}}}}"#
            )),
            "invalid length 2".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","cloud_scale":0}}"#
            )),
            "unit scale 0 must be finite and > 0".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","mesh_scale":0.001}}"#
            )),
            "'mesh_scale' needs a 'mesh'".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{}"}}"#,
                example_str("step_block.stl")
            )),
            "unknown format".to_owned(),
        ),
        (
            envelope(&format!(
                r#"{{"command":"align-cloud","cloud":"{scan}","cloud_scale":0.001,"start_pose":{{"xyz":[5,5,5],"rpy":[0,0,0]}}}}"#
            )),
            "cannot align: only 0 cloud points lie within delta".to_owned(),
        ),
    ];
    for (request, reason) in &cases {
        let reply = fixture.send_text(request);
        assert_eq!(reply["ok"], false, "{request}: {reply}");
        let got = reply["reason"].as_str().unwrap();
        assert!(got.contains(reason.as_str()), "{request}: {got}");
        let status = fixture.call(json!({"command": "status"}));
        assert_eq!(status["ok"], true, "after {request}: {status}");
        assert_eq!(status["data"]["inspections"], 9, "{status}");
    }

    // The client command: exit 2 with the service's reason on one line.
    let output = ips(&[
        "align-cloud",
        "--service",
        &fixture.service.rep_endpoint,
        "--cloud",
        "/no/such/scan.xyz",
    ]);
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("'/no/such/scan.xyz': No such file"),
        "{stderr}"
    );
    fixture.finish();
}
