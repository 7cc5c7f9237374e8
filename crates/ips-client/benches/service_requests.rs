//! How long the alignment service's slow requests take, and how long a `status` request sent
//! meanwhile waits for them (the service answers in turn from one thread). The service runs in
//! this process over loopback TCP, on the shipped step block example:
//!
//! - `diagnose` on 16 tilted touches (`align_core::trials::probing::step_block_diagnosis_touches`,
//!   planned by IK at the true part pose): once with a 3.4 mm ball declared as 3 mm (every
//!   candidate effect is fitted), once with nothing undeclared (the chi-square test stops early);
//! - `align-cloud` on `examples/step_block_ur10/scan.xyz` with the service's defaults (the
//!   session part from its nominal pose, delta 0.1 m).
//!
//! Prints a Markdown table of round trips as a client sees them.
//!
//!     cargo bench -p ips-client --bench service_requests -- [RUNS]   (default 5)

use std::path::{Path, PathBuf};
use std::time::Instant;

use align_core::pose::isometry_from_xyz_rpy;
use align_core::trials::probing::{step_block_diagnosis_touches, tilted_joint_targets};
use align_service::session::LoadedSession;
use protocol::session::{Inspection, SessionFile};
use serde_json::{Value, json};

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).expect("example file");
    serde_json::from_str(&text).expect("example JSON")
}

/// The example session with 16 touches planned at the true pose by a probe whose ball has
/// `true_radius_m` (the session keeps declaring its own radius), paths made absolute.
fn sixteen_touch_session(true_radius_m: f64) -> SessionFile {
    let mut file: SessionFile =
        serde_json::from_value(read_json(&example("session.json"))).expect("session");
    let folder = example("");
    let loaded = LoadedSession::resolve(file.clone(), &folder).expect("example session");
    let truth = read_json(&example("truth.json"));
    let array =
        |v: &Value| -> [f64; 3] { std::array::from_fn(|i| v[i].as_f64().expect("truth number")) };
    let base_from_part = isometry_from_xyz_rpy(
        array(&truth["base_from_part"]["xyz"]),
        array(&truth["base_from_part"]["rpy"]),
    );
    let seed = file.inspections[0]
        .q
        .clone()
        .expect("the example gives joints");
    let chain = loaded.chain.as_ref().expect("the example has a robot");
    let targets = tilted_joint_targets(
        chain,
        &base_from_part,
        &loaded.tool.flange_from_tcp,
        true_radius_m,
        1.0,
        &step_block_diagnosis_touches(),
        &seed,
    )
    .expect("the 16 touches are reachable");
    file.inspections = targets
        .into_iter()
        .enumerate()
        .map(|(index, q)| Inspection {
            id: (index + 1).to_string(),
            q: Some(q),
            flange_pose: None,
            qd: None,
            stamp: None,
            face: None,
            trigger: None,
        })
        .collect();
    let absolute = |relative: &str| folder.join(relative).display().to_string();
    if let Some(robot) = &mut file.robot {
        robot.urdf = absolute(&robot.urdf);
    }
    file.part.mesh = absolute(&file.part.mesh);
    file
}

fn socket(context: &zmq::Context, kind: zmq::SocketType) -> zmq::Socket {
    let socket = context.socket(kind).expect("socket");
    socket.set_linger(0).expect("linger");
    socket.set_rcvtimeo(60_000).expect("timeout");
    socket
}

fn request(body: Value) -> String {
    json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body}).to_string()
}

/// One round trip; returns the reply body and the seconds it took.
fn round_trip(client: &zmq::Socket, body: &Value) -> (Value, f64) {
    let started = Instant::now();
    client
        .send(request(body.clone()).as_bytes(), 0)
        .expect("send");
    let reply = client.recv_bytes(0).expect("the service replies");
    let seconds = started.elapsed().as_secs_f64();
    let reply: Value = serde_json::from_slice(&reply).expect("reply JSON");
    assert_eq!(reply["body"]["ok"], true, "{reply}");
    (reply["body"].clone(), seconds)
}

/// A status request sent on another socket 10 ms after `slow` went out: how long status
/// waits. Returns (status seconds, slow request seconds).
fn status_behind(
    slow_client: &zmq::Socket,
    status_client: &zmq::Socket,
    slow: &Value,
) -> (f64, f64) {
    let started = Instant::now();
    slow_client
        .send(request(slow.clone()).as_bytes(), 0)
        .expect("send");
    // The service gives no sign that it has taken a request; sent at once, the status could
    // reach the socket's fair queue first and be answered first, which is not the case to
    // measure. (A benchmark, so a pause cannot make a test flaky.)
    std::thread::sleep(std::time::Duration::from_millis(10));
    let (_, status_s) = round_trip(status_client, &json!({"command": "status"}));
    slow_client.recv_bytes(0).expect("the slow request's reply");
    (status_s, started.elapsed().as_secs_f64())
}

struct Row {
    what: String,
    seconds: Vec<f64>,
    note: String,
}

fn print_table(rows: &[Row]) {
    println!("| request | runs | median (ms) | min (ms) | max (ms) | note |");
    println!("| --- | ---: | ---: | ---: | ---: | --- |");
    for row in rows {
        let mut sorted = row.seconds.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        println!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {} |",
            row.what,
            sorted.len(),
            median * 1e3,
            sorted[0] * 1e3,
            sorted[sorted.len() - 1] * 1e3,
            row.note
        );
    }
}

fn main() {
    let runs: usize = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with("--"))
        .and_then(|a| a.parse().ok())
        .unwrap_or(5)
        .max(1);
    let folder = std::env::temp_dir().join(format!("cobot-align-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).expect("scratch folder");
    let example_session: SessionFile =
        serde_json::from_value(read_json(&example("session.json"))).expect("session");
    let declared_radius_m = example_session.tool.tip_radius;
    let sessions = [
        ("ball 0.4 mm larger than declared", 0.0004),
        ("nothing undeclared", 0.0),
    ]
    .map(|(name, extra_radius_m)| {
        let path = folder.join(format!("sixteen_{}.json", name.replace(' ', "_")));
        let file = sixteen_touch_session(declared_radius_m + extra_radius_m);
        let text = serde_json::to_string_pretty(&file).expect("session JSON");
        std::fs::write(&path, text).expect("write session");
        (name, path)
    });

    let context = zmq::Context::new();
    // Stand-ins for robot-bridge: nothing here asks for mirroring.
    let bridge_rep = socket(&context, zmq::REP);
    bridge_rep.bind("tcp://127.0.0.1:*").expect("bind");
    let bridge_pub = socket(&context, zmq::PUB);
    bridge_pub.bind("tcp://127.0.0.1:*").expect("bind");
    let endpoint = |s: &zmq::Socket| s.get_last_endpoint().expect("endpoint").expect("utf-8");
    let service = align_service::server::start(&align_service::server::Config {
        session: sessions[0].1.clone(),
        journal: folder.join("inspections.journal"),
        rep: "tcp://127.0.0.1:*".to_owned(),
        bridge_rep: endpoint(&bridge_rep),
        bridge_pub: endpoint(&bridge_pub),
        max_sample_age_s: 0.1,
        max_tool_speed_m_s: 0.005,
        data_dirs: vec![folder.clone()],
        keep_session_inspections: true,
        trigger: None,
    })
    .expect("service starts");
    let client = socket(&context, zmq::REQ);
    client.connect(&service.rep_endpoint).expect("connect");
    let second_client = socket(&context, zmq::REQ);
    second_client
        .connect(&service.rep_endpoint)
        .expect("connect");

    let status = json!({"command": "status"});
    let diagnose = json!({"command": "diagnose"});
    let align_cloud = json!({"command": "align-cloud", "cloud": example("scan.xyz").display().to_string(), "cloud_scale": 0.001});
    let mut rows = Vec::new();
    let idle: Vec<f64> = (0..200).map(|_| round_trip(&client, &status).1).collect();
    rows.push(Row {
        what: "status, service idle".to_owned(),
        seconds: idle,
        note: String::new(),
    });
    for (name, path) in &sessions {
        round_trip(
            &client,
            &json!({"command": "load", "path": path.display().to_string()}),
        );
        let mut verdict = String::new();
        let seconds = (0..runs)
            .map(|_| {
                let (reply, seconds) = round_trip(&client, &diagnose);
                verdict = reply["data"]["verdict"].as_str().unwrap_or("?").to_owned();
                seconds
            })
            .collect();
        rows.push(Row {
            what: format!("diagnose, 16 touches, {name}"),
            seconds,
            note: format!("verdict {verdict}"),
        });
    }
    let mut note = String::new();
    let seconds = (0..runs)
        .map(|_| {
            let (reply, seconds) = round_trip(&client, &align_cloud);
            let data = &reply["data"];
            note = format!(
                "{} points, {} runs, {} iterations, PCA's own time {:.1} ms",
                data["cloud_points"],
                data["starts"],
                data["iterations"],
                data["time_s"].as_f64().unwrap_or(f64::NAN) * 1e3
            );
            seconds
        })
        .collect();
    rows.push(Row {
        what: "align-cloud, examples/step_block_ur10/scan.xyz".to_owned(),
        seconds,
        note,
    });
    // The effect session is the slow one: status behind it is the worst wait.
    round_trip(
        &client,
        &json!({"command": "load", "path": sessions[0].1.display().to_string()}),
    );
    for (what, slow) in [
        ("a diagnose (ball radius)", &diagnose),
        ("an align-cloud", &align_cloud),
    ] {
        let (status_s, slow_s): (Vec<f64>, Vec<f64>) = (0..runs)
            .map(|_| status_behind(&client, &second_client, slow))
            .unzip();
        let mut sorted = slow_s;
        sorted.sort_by(f64::total_cmp);
        rows.push(Row {
            what: format!("status, sent 10 ms after {what}"),
            seconds: status_s,
            note: format!(
                "{what} itself: median {:.1} ms",
                sorted[sorted.len() / 2] * 1e3
            ),
        });
    }
    print_table(&rows);
    service.stop();
    let _ = std::fs::remove_dir_all(&folder);
}
