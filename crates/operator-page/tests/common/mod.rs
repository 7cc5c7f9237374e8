//! A simulated cell (sim-robot, robot-bridge, the alignment service) in this process, and a
//! raw HTTP/1.1 client: the page's wire as a browser sees it, without an HTTP client crate.

#![allow(clippy::unwrap_used, dead_code)] // Tests: a panic is the failure report.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;
use serde_json::{Value, json};

pub fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

pub struct SimCell {
    pub sim: sim_robot::SimHandle,
    pub bridge: robot_bridge::Handle,
    pub service: align_service::server::Handle,
    pub session: PathBuf,
    /// The example session's planned touches (joints, rad): holding the simulator at each
    /// gives a touch of the hidden part.
    pub planned: Vec<Vec<f64>>,
    /// The session's folder. Last, so that it is removed after the service (which journals
    /// into it) has stopped.
    _folder: Scratch,
}

/// A scratch folder that is removed when this is dropped, also when an assertion fails and the
/// test unwinds, so that runs leave nothing in the temp folder.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        // Best effort: a leftover folder is no reason to fail a test.
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The example session without its inspections, paths made absolute, in a fresh folder.
fn template(name: &str) -> (Scratch, PathBuf, Vec<Vec<f64>>) {
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    let planned = template["inspections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| serde_json::from_value(i["q"].clone()).unwrap())
        .collect();
    template["inspections"] = json!([]);
    template["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    let folder =
        std::env::temp_dir().join(format!("cobot-align-page-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    let scratch = Scratch(folder.clone());
    std::fs::create_dir_all(&folder).unwrap();
    let session = folder.join("template.json");
    std::fs::write(&session, template.to_string()).unwrap();
    (scratch, session, planned)
}

impl SimCell {
    pub fn start(name: &str) -> Self {
        let sim = sim_robot::start(&sim_robot::Config {
            robot: ShippedRobot::Ur10,
            rtde_listen: "127.0.0.1:0".to_owned(),
            primary_listen: None,
            calibration: None,
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: sim_robot::FriSettings::default(),
        })
        .unwrap();
        let bridge = robot_bridge::start(&robot_bridge::Config {
            backend: robot_bridge::BackendConfig::Ur(robot_bridge::backend::ur::UrConfig {
                robot_host: "127.0.0.1".to_owned(),
                rtde_port: sim.rtde_port().unwrap(),
                primary_port: None,
            }),
            rep: "tcp://127.0.0.1:*".to_owned(),
            publish: "tcp://127.0.0.1:*".to_owned(),
        })
        .unwrap();
        let (folder, session, planned) = template(name);
        let service = align_service::server::start(&align_service::server::Config {
            session: session.clone(),
            journal: session.with_file_name("inspections.journal"),
            rep: "tcp://127.0.0.1:*".to_owned(),
            bridge_rep: bridge.rep_endpoint.clone(),
            bridge_pub: bridge.pub_endpoint.clone(),
            max_sample_age_s: 0.1,
            max_tool_speed_m_s: 0.005,
            data_dirs: vec![],
            keep_session_inspections: true,
            trigger: None,
        })
        .unwrap();
        Self {
            sim,
            bridge,
            service,
            session,
            planned,
            _folder: folder,
        }
    }

    pub fn page(&self) -> operator_page::Handle {
        operator_page::start(&operator_page::Config {
            listen: "127.0.0.1:0".to_owned(),
            service: self.service.rep_endpoint.clone(),
            bridge_rep: self.bridge.rep_endpoint.clone(),
            bridge_pub: self.bridge.pub_endpoint.clone(),
            session: self.session.clone(),
            reply_timeout: Duration::from_secs(10),
        })
        .unwrap()
    }

    /// Holds the simulated robot at `q` and returns once the bridge's stream has shown it and
    /// two samples more (the service's own subscription has seen it by then).
    pub fn hold(&self, context: &zmq::Context, q: &[f64]) {
        let control = req(context, &self.sim.control_endpoint);
        let command = json!({"command": "motion", "motion": {"kind": "hold", "q": q}});
        control.send(command.to_string().as_bytes(), 0).unwrap();
        control.recv_bytes(0).unwrap();
        let sub = context.socket(zmq::SUB).unwrap();
        sub.set_linger(0).unwrap();
        sub.set_rcvtimeo(5000).unwrap();
        sub.set_subscribe(b"").unwrap();
        sub.connect(&self.bridge.pub_endpoint).unwrap();
        let mut after: Option<i32> = None;
        while after.is_none_or(|n| n < 2) {
            let state: Value = serde_json::from_slice(&sub.recv_bytes(0).unwrap()).unwrap();
            let at_pose = state["body"]["position"]
                .as_array()
                .unwrap()
                .iter()
                .zip(q)
                .all(|(a, b)| (a.as_f64().unwrap() - b).abs() < 1e-12);
            after = match (after, at_pose) {
                (None, true) => Some(0),
                (Some(n), _) => Some(n + 1),
                (None, false) => None,
            };
        }
    }
}

pub fn req(context: &zmq::Context, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

/// One request to the service over ZeroMQ, as another client (`ips`) would send it.
pub fn call(socket: &zmq::Socket, body: Value) -> Value {
    let request =
        json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body});
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    let reply: Value = serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap();
    reply["body"].clone()
}

/// An HTTP response: status code, headers (lower-case names) and body.
#[derive(Debug)]
pub struct Response {
    pub status: u16,
    pub headers: String,
    pub body: String,
}

impl Response {
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.body).unwrap_or_else(|e| panic!("not JSON ({e}): {}", self.body))
    }
}

/// One HTTP/1.1 request, the connection closed after it.
pub fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    content_type: Option<&str>,
    body: &[u8],
) -> Response {
    request(addr, &addr.to_string(), method, path, content_type, body)
}

/// A JSON command to the page as if it were named `host`.
pub fn http_with_host(addr: SocketAddr, host: &str, body: &[u8]) -> Response {
    request(
        addr,
        host,
        "POST",
        "/api/command",
        Some("application/json"),
        body,
    )
}

fn request(
    addr: SocketAddr,
    host: &str,
    method: &str,
    path: &str,
    content_type: Option<&str>,
    body: &[u8],
) -> Response {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let mut head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    if let Some(content_type) = content_type {
        head.push_str(&format!("Content-Type: {content_type}\r\n"));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes()).unwrap();
    // A server may answer (and close) before reading an oversized body: a failed write is fine.
    let _ = stream.write_all(body);
    let mut raw = Vec::new();
    let _ = stream.read_to_end(&mut raw);
    let text = String::from_utf8_lossy(&raw).into_owned();
    let (headers, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = headers
        .split_whitespace()
        .nth(1)
        .and_then(|code| code.parse().ok())
        .unwrap_or_else(|| panic!("no status line: {text}"));
    Response {
        status,
        headers: headers.to_ascii_lowercase(),
        body: body.to_owned(),
    }
}

pub fn get(addr: SocketAddr, path: &str) -> Response {
    http(addr, "GET", path, None, b"")
}

pub fn command(addr: SocketAddr, body: Value) -> Response {
    http(
        addr,
        "POST",
        "/api/command",
        Some("application/json"),
        body.to_string().as_bytes(),
    )
}

/// An open `GET /api/events` stream.
pub struct Events {
    reader: BufReader<TcpStream>,
}

impl Events {
    pub fn open(addr: SocketAddr) -> Self {
        let mut stream = TcpStream::connect(addr).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(1)))
            .unwrap();
        let head = format!(
            "GET /api/events HTTP/1.1\r\nHost: {addr}\r\nAccept: text/event-stream\r\n\r\n"
        );
        stream.write_all(head.as_bytes()).unwrap();
        Self {
            reader: BufReader::new(stream),
        }
    }

    /// Waits up to `within` for an event named `name` whose data satisfies `wanted`, returning
    /// that data. Each event is one `event:` line and one `data:` line of JSON (chunk-size
    /// lines of the chunked encoding in between are skipped).
    pub fn wait_for(
        &mut self,
        name: &str,
        within: Duration,
        wanted: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + within;
        let mut current: Option<String> = None;
        let mut seen = Vec::new();
        while Instant::now() < deadline {
            let mut line = String::new();
            match self.reader.read_line(&mut line) {
                Ok(0) => panic!("the event stream closed; seen: {seen:?}"),
                Ok(_) => {}
                // A read timeout: nothing yet, look at the deadline again.
                Err(_) => continue,
            }
            let line = line.trim_end();
            if let Some(event) = line.strip_prefix("event: ") {
                current = Some(event.to_owned());
            } else if let Some(data) = line.strip_prefix("data: ") {
                if current.as_deref() == Some(name) {
                    let value: Value = serde_json::from_str(data).unwrap();
                    if wanted(&value) {
                        return value;
                    }
                }
                if seen.len() < 5 {
                    seen.push(format!("{current:?}: {}", &data[..data.len().min(200)]));
                }
            }
        }
        panic!("no '{name}' event as wanted within {within:?}; first seen: {seen:?}")
    }
}
