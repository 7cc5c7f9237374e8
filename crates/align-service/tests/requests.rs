//! Requests the fault test sent the service: refused with a reason that names what is wrong,
//! nothing journaled, and the service keeps serving.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};

use align_service::server::{Config, Handle, start};
use serde_json::{Value, json};

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

/// A service on `session` with its journal and data directory in `folder`, no bridge (these
/// requests never reach it), keeping or dropping the session file's inspections.
fn config(session: PathBuf, folder: &Path, keep_session_inspections: bool) -> Config {
    Config {
        session,
        journal: folder.join("inspections.journal"),
        rep: "tcp://127.0.0.1:*".to_owned(),
        bridge_rep: "tcp://127.0.0.1:1".to_owned(),
        bridge_pub: "tcp://127.0.0.1:1".to_owned(),
        max_sample_age_s: 0.1,
        max_tool_speed_m_s: 0.005,
        data_dirs: vec![folder.to_path_buf()],
        keep_session_inspections,
        trigger: None,
    }
}

struct Fixture {
    service: Handle,
    socket: zmq::Socket,
    folder: PathBuf,
    _context: zmq::Context,
}

impl Fixture {
    fn start(name: &str) -> Self {
        let folder = std::env::temp_dir().join(format!(
            "cobot-align-requests-{name}-{}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&folder);
        std::fs::create_dir_all(&folder).unwrap();
        let service = start(&config(example("session.json"), &folder, true)).unwrap();
        let context = zmq::Context::new();
        let socket = context.socket(zmq::REQ).unwrap();
        socket.set_linger(0).unwrap();
        socket.set_rcvtimeo(10_000).unwrap();
        socket.connect(&service.rep_endpoint).unwrap();
        Self {
            service,
            socket,
            folder,
            _context: context,
        }
    }

    fn send(&self, text: &str) -> Value {
        self.socket.send(text.as_bytes(), 0).unwrap();
        serde_json::from_slice(&self.socket.recv_bytes(0).unwrap()).unwrap()
    }

    fn call(&self, body: Value) -> Value {
        let request =
            json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body});
        self.send(&request.to_string())["body"].clone()
    }

    fn journal_len(&self) -> u64 {
        std::fs::metadata(self.folder.join("inspections.journal"))
            .unwrap()
            .len()
    }

    fn finish(self) {
        self.service.stop();
        let _ = std::fs::remove_dir_all(&self.folder);
    }
}

#[test]
fn arrays_in_place_of_objects_are_refused_and_nothing_is_wiped() {
    let fixture = Fixture::start("arrays");
    let before = fixture.journal_len();
    let reply = fixture.send(r#"[["a","b","c"],["reset"]]"#);
    assert_eq!(reply["body"]["ok"], false, "{reply}");
    let reason = reply["body"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("expected a JSON object, got an array"),
        "{reason}"
    );
    assert_eq!(fixture.journal_len(), before);
    assert_eq!(
        fixture.call(json!({"command": "status"}))["data"]["inspections"],
        9
    );
    fixture.finish();
}

#[test]
fn load_refuses_inspections_the_robot_could_not_have_reported_before_journaling() {
    let fixture = Fixture::start("load");
    let template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    let cases = [
        (
            json!([0.1, -1.2, 1.4, -1.8, -1.57]),
            "expected 6 joint values",
        ),
        (json!([]), "expected 6 joint values"),
        (
            json!([1e300, -1.2, 1.4, -1.8, -1.57, 0.0]),
            "outside its limits",
        ),
    ];
    for (index, (q, reason)) in cases.into_iter().enumerate() {
        let mut session = template.clone();
        session["inspections"][3]["q"] = q.clone();
        // The example's relative paths are the service's session folder's.
        session["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
        session["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
        let path = fixture.folder.join(format!("bad{index}.json"));
        std::fs::write(&path, session.to_string()).unwrap();
        let before = fixture.journal_len();
        let reply = fixture.call(json!({"command": "load", "path": path.to_str().unwrap()}));
        assert_eq!(reply["ok"], false, "{q}: {reply}");
        let why = reply["reason"].as_str().unwrap();
        assert!(
            why.contains(reason) && why.contains("inspection '4'"),
            "{q}: {why}"
        );
        assert_eq!(fixture.journal_len(), before, "{q}: journaled anyway");
        let aligned = fixture.call(json!({"command": "align"}));
        assert_eq!(aligned["ok"], true, "{q}: the next align fails: {aligned}");
    }
    fixture.finish();
}

#[test]
fn files_outside_the_data_directories_fifos_and_devices_are_refused_without_stalling() {
    let fixture = Fixture::start("files");
    let fifo = fixture.folder.join("fifo.json");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let cases = [
        (
            json!({"command": "load", "path": fifo.to_str().unwrap()}),
            "is not a regular file",
        ),
        (
            json!({"command": "load", "path": "/dev/zero"}),
            "outside the service's data directories",
        ),
        (
            json!({"command": "load", "path": example("session.json").to_str().unwrap()}),
            "outside the service's data directories",
        ),
        (
            json!({"command": "save", "path": "/tmp/../etc/cobot-align-should-not-exist.json"}),
            "outside the service's data directories",
        ),
        (
            json!({"command": "align-cloud", "cloud": example("scan.xyz").to_str().unwrap()}),
            "outside the service's data directories",
        ),
    ];
    for (request, reason) in cases {
        // A FIFO would block a plain read until a writer comes: the reply arrives at once.
        let reply = fixture.call(request.clone());
        assert_eq!(reply["ok"], false, "{request}: {reply}");
        let why = reply["reason"].as_str().unwrap();
        assert!(why.contains(reason), "{request}: {why}");
        assert_eq!(fixture.call(json!({"command": "status"}))["ok"], true);
    }
    // Inside the data directory, save and load work.
    let saved = fixture.folder.join("saved.json");
    let reply = fixture.call(json!({"command": "save", "path": saved.to_str().unwrap()}));
    assert_eq!(reply["ok"], true, "{reply}");
    let reply = fixture.call(json!({"command": "load", "path": saved.to_str().unwrap()}));
    assert_eq!(reply["data"]["inspections"], 9, "{reply}");
    fixture.finish();
}

#[test]
fn the_vendored_libzmq_has_no_curve_as_the_readme_says() {
    // The README's security notes say the sockets are unauthenticated and unencrypted; this
    // pins the fact they rest on.
    assert_ne!(zmq::has("curve"), Some(true));
}

#[test]
fn raw_tcp_garbage_and_multipart_requests_do_not_stop_the_service() {
    use std::io::Write;
    let fixture = Fixture::start("garbage");
    let address = fixture
        .service
        .rep_endpoint
        .trim_start_matches("tcp://")
        .to_owned();
    let mut garbage = std::net::TcpStream::connect(&address).unwrap();
    // A ZMTP-looking start, then noise: what made a plain REP socket stop answering everyone.
    garbage
        .write_all(&[
            0xFF, 0, 0, 0, 0, 0, 0, 0, 1, 0x7F, 0x13, 0x37, 0x00, 0xFF, 0x42,
        ])
        .unwrap();
    assert_eq!(fixture.call(json!({"command": "status"}))["ok"], true);
    drop(garbage);
    fixture
        .socket
        .send_multipart([br#"{"header":{}}"#.as_slice(), b"junk"], 0)
        .unwrap();
    let reply: Value = serde_json::from_slice(&fixture.socket.recv_bytes(0).unwrap()).unwrap();
    let why = reply["body"]["reason"].as_str().unwrap();
    assert!(why.contains("multipart request of 2 frames"), "{why}");
    assert_eq!(fixture.call(json!({"command": "status"}))["ok"], true);
    fixture.finish();
}

/// A session file that already holds inspections: a new journal keeps them (and the start-up
/// note says so) unless told to drop them; an existing journal wins, and the note says that the
/// file's are not used.
#[test]
fn the_session_files_inspections_are_kept_or_dropped_and_the_start_says_which() {
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-requests-session-inspections-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).unwrap();
    let config = |keep: bool| config(example("session.json"), &folder, keep);
    let count = |service: &Handle| {
        let context = zmq::Context::new();
        let socket = context.socket(zmq::REQ).unwrap();
        socket.set_linger(0).unwrap();
        socket.set_rcvtimeo(10_000).unwrap();
        socket.connect(&service.rep_endpoint).unwrap();
        let request = json!({"header": {"from": "ips", "to": "align", "type": "request"},
                             "body": {"command": "status"}});
        socket.send(request.to_string().as_bytes(), 0).unwrap();
        let reply: Value = serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap();
        reply["body"]["data"]["inspections"].as_u64().unwrap()
    };
    let dropped = start(&config(false)).unwrap();
    assert_eq!(count(&dropped), 0);
    assert!(
        dropped
            .inspections_note
            .contains("the session file's 9 inspection(s) are not used"),
        "{}",
        dropped.inspections_note
    );
    dropped.stop();
    // The journal of that run exists now (empty): it continues, with the file's left out.
    let continued = start(&config(true)).unwrap();
    assert_eq!(count(&continued), 0);
    assert!(
        continued
            .inspections_note
            .contains("0 inspection(s) replayed from the journal"),
        "{}",
        continued.inspections_note
    );
    assert!(
        continued
            .inspections_note
            .contains("the session file's 9 are not used")
    );
    continued.stop();
    std::fs::remove_file(folder.join("inspections.journal")).unwrap();
    let kept = start(&config(true)).unwrap();
    assert_eq!(count(&kept), 9);
    assert!(
        kept.inspections_note
            .contains("9 inspection(s) from the session file start the list"),
        "{}",
        kept.inspections_note
    );
    kept.stop();
    let _ = std::fs::remove_dir_all(&folder);
}

/// `results` gives the latest alignment and diagnosis whoever asked for them, says whether they
/// still describe the inspections held, and `status` counts them so a client knows when to ask.
#[test]
fn results_hold_the_latest_alignment_and_diagnosis_and_say_when_they_are_stale() {
    let fixture = Fixture::start("results");
    let empty = fixture.call(json!({"command": "results"}));
    assert_eq!(empty["ok"], true, "{empty}");
    assert_eq!(empty["data"], json!({"serial": 0}));
    let aligned = fixture.call(json!({"command": "align"}));
    assert_eq!(aligned["ok"], true, "{aligned}");
    let status = fixture.call(json!({"command": "status"}));
    assert_eq!(status["data"]["results_serial"], 1);
    let results = fixture.call(json!({"command": "results"}))["data"].clone();
    assert_eq!(results["serial"], 1);
    assert_eq!(results["alignment"]["current"], true);
    assert_eq!(results["alignment"]["report"], aligned["data"]);
    assert_eq!(
        results["alignment"]["inspections"]
            .as_array()
            .unwrap()
            .len(),
        9
    );
    assert!(results.get("diagnosis").is_none(), "{results}");
    let diagnosed = fixture.call(json!({"command": "diagnose"}));
    assert_eq!(diagnosed["ok"], true, "{diagnosed}");
    assert!(diagnosed["data"]["noise_sigma_m"].as_f64().unwrap() > 0.0);
    let first = results["alignment"]["inspections"][0].clone();
    let removed = fixture.call(json!({"command": "remove", "ids": [first]}));
    assert_eq!(removed["ok"], true, "{removed}");
    let results = fixture.call(json!({"command": "results"}))["data"].clone();
    assert_eq!(results["serial"], 2);
    assert_eq!(results["alignment"]["current"], false);
    assert_eq!(results["diagnosis"]["current"], false);
    assert_eq!(results["diagnosis"]["report"], diagnosed["data"]);
    assert_eq!(results["alignment"]["serial"], 1);
    assert_eq!(results["diagnosis"]["serial"], 2);
    fixture.finish();
}

/// `list` places every ball where `align` does: through the session's declared joint
/// corrections (here a 2 mrad shoulder offset, which moves the balls by about a millimetre).
#[test]
fn list_places_the_balls_as_align_does_with_the_sessions_joint_corrections() {
    let folder =
        std::env::temp_dir().join(format!("cobot-align-requests-balls-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).unwrap();
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    let absolute = |relative: &Value| json!(example(relative.as_str().unwrap()));
    session["robot"]["urdf"] = absolute(&session["robot"]["urdf"]);
    session["part"]["mesh"] = absolute(&session["part"]["mesh"]);
    session["robot"]["joint_offsets"] = json!([0.0, 0.002, 0.0, 0.0, 0.0, 0.0]);
    let path = folder.join("corrected.json");
    std::fs::write(&path, session.to_string()).unwrap();
    let service = start(&config(path.clone(), &folder, true)).unwrap();
    let context = zmq::Context::new();
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.connect(&service.rep_endpoint).unwrap();
    let request = json!({"header": {"from": "ips", "to": "align", "type": "request"},
                         "body": {"command": "list"}});
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    let reply: Value = serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap();
    let balls = reply["body"]["data"]["balls"].as_array().unwrap().clone();
    let corrected = align_service::session::LoadedSession::load(&path).unwrap();
    let nominal = align_service::session::LoadedSession::load(&example("session.json")).unwrap();
    assert_eq!(balls.len(), corrected.touches.len());
    for ((ball, touch), uncorrected) in balls.iter().zip(&corrected.touches).zip(&nominal.touches) {
        assert_eq!(ball["id"], touch.id.as_str());
        let centre_m: Vec<f64> = (0..3)
            .map(|axis| ball["centre_mm"][axis].as_f64().unwrap() * 1e-3)
            .collect();
        let from = |p: &nalgebra::Point3<f64>| {
            (0..3)
                .map(|axis| (centre_m[axis] - p[axis]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        assert!(from(&touch.point) < 1e-9, "{ball} vs {:?}", touch.point);
        assert!(from(&uncorrected.point) > 5e-4, "the offset moves the ball");
    }
    service.stop();
    let _ = std::fs::remove_dir_all(&folder);
}
