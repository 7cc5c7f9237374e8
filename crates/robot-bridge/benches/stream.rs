//! Streaming benchmark on loopback: sim-robot (in this process) -> the robot-bridge binary (a
//! child process, so its CPU is its own) -> 4 ZeroMQ subscribers (threads here). For the UR10e
//! (RTDE at 500 Hz) and the iiwa (FRI at 1 kHz), prints a table per back end: achieved rate,
//! bridge sequence gaps, latency from the controller's sample time to each subscriber's receipt,
//! the bridge's CPU, and the instruction round trip.
//!
//!     cargo bench -p robot-bridge --bench stream -- [SECONDS] [ur|iiwa]   (default 10 s, both)

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use align_core::robots::ShippedRobot;
use cell::ChildProcess;

const STATUS: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"status","content":"bridge"}}"#;
const START: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"start","content":"hwState"}}"#;

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// User + system CPU seconds of a process, from /proc/PID/stat (clock ticks of 10 ms).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks: f64 = fields.get(11).and_then(|v| v.parse().ok()).unwrap_or(0.0)
        + fields.get(12).and_then(|v| v.parse().ok()).unwrap_or(0.0);
    ticks / 100.0
}

fn socket(context: &zmq::Context, kind: zmq::SocketType, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(kind).expect("socket");
    socket.set_linger(0).expect("linger");
    socket.set_rcvtimeo(2000).expect("timeout");
    socket.connect(endpoint).expect("connect");
    socket
}

/// The bridge binary as a child process, through the launcher `ips demo` and the tests use.
fn spawn_bridge(args: &[&str]) -> ChildProcess {
    let mut args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
    args.extend(["--rep", "tcp://127.0.0.1:*", "--pub", "tcp://127.0.0.1:*"].map(str::to_owned));
    let program = Path::new(env!("CARGO_BIN_EXE_robot-bridge"));
    cell::spawn("robot-bridge", program, &args, cell::READY_WITHIN).expect("robot-bridge starts")
}

fn main() {
    let arguments: Vec<String> = std::env::args().skip(1).collect();
    let seconds: f64 = arguments
        .iter()
        .filter_map(|a| a.parse().ok())
        .next()
        .unwrap_or(10.0);
    let only = arguments
        .iter()
        .find(|a| matches!(a.as_str(), "ur" | "iiwa"))
        .cloned();
    if only.as_deref() != Some("iiwa") {
        let sim = sim_robot::start(&sim_robot::Config {
            robot: ShippedRobot::Ur10e,
            rtde_listen: "127.0.0.1:0".to_owned(),
            primary_listen: None,
            calibration: None,
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: sim_robot::FriSettings::default(),
        })
        .expect("sim-robot");
        let port = sim.rtde_port().expect("port").to_string();
        let bridge = spawn_bridge(&[
            "--backend",
            "ur",
            "--robot-host",
            "127.0.0.1",
            "--rtde-port",
            &port,
            "--no-calibration",
        ]);
        measure(
            &bridge,
            sim.clock_origin_unix_s,
            seconds,
            "UR10e, RTDE at 500 Hz",
        );
        sim.stop();
    }
    if only.as_deref() != Some("ur") {
        let bridge = spawn_bridge(&[
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--fri-port",
            "0",
        ]);
        let port = bridge.port("fri").expect("fri endpoint");
        let sim = sim_robot::start(&sim_robot::Config {
            robot: ShippedRobot::Iiwa14,
            rtde_listen: String::new(),
            primary_listen: None,
            calibration: None,
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: sim_robot::FriSettings {
                target: format!("127.0.0.1:{port}"),
                send_period_ms: 1,
                receive_multiplier: 1,
                trigger_io: None,
            },
        })
        .expect("sim-robot");
        measure(
            &bridge,
            sim.clock_origin_unix_s,
            seconds,
            "iiwa 14, FRI at 1 kHz",
        );
        sim.stop();
    }
}

fn measure(bridge: &ChildProcess, origin: f64, seconds: f64, label: &str) {
    let context = zmq::Context::new();
    let rep = socket(
        &context,
        zmq::REQ,
        bridge.endpoint("rep").expect("rep endpoint"),
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        rep.send(STATUS, 0).expect("send");
        let reply = rep.recv_string(0).expect("reply").unwrap_or_default();
        if reply.contains("\"connected\"") || Instant::now() > deadline {
            break;
        }
        thread::sleep(Duration::from_millis(20));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let subscribers: Vec<_> = (0..4)
        .map(|_| {
            let sub = socket(
                &context,
                zmq::SUB,
                bridge.endpoint("pub").expect("pub endpoint"),
            );
            sub.set_subscribe(b"").expect("subscribe");
            let stop = Arc::clone(&stop);
            thread::spawn(move || {
                let (mut latencies, mut gaps, mut count, mut last_seq) =
                    (Vec::new(), 0u64, 0u64, None::<u64>);
                while !stop.load(Ordering::Relaxed) {
                    let Ok(bytes) = sub.recv_bytes(0) else {
                        continue;
                    };
                    let received = unix_now();
                    let Ok(value) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
                        continue;
                    };
                    let body = &value["body"];
                    let seq = body["seq"].as_u64().unwrap_or(0);
                    if let Some(last) = last_seq {
                        gaps += seq.saturating_sub(last + 1);
                    }
                    last_seq = Some(seq);
                    count += 1;
                    latencies.push(
                        received - (origin + body["controller_time"].as_f64().unwrap_or(0.0)),
                    );
                }
                (latencies, gaps, count)
            })
        })
        .collect();
    // Let the subscriptions reach the publisher before the stream starts.
    thread::sleep(Duration::from_millis(300));
    rep.send(START, 0).expect("send");
    let _ = rep.recv_string(0);
    let pid = bridge.child.id();
    let cpu_before = cpu_seconds(pid);
    let started = Instant::now();
    thread::sleep(Duration::from_secs_f64(seconds));
    let elapsed = started.elapsed().as_secs_f64();
    let cpu = cpu_seconds(pid) - cpu_before;
    let mut round_trips = Vec::new();
    for _ in 0..1000 {
        let sent = Instant::now();
        rep.send(STATUS, 0).expect("send");
        let _ = rep.recv_bytes(0);
        round_trips.push(sent.elapsed().as_secs_f64());
    }
    stop.store(true, Ordering::Relaxed);
    println!("\n### {label}, {seconds} s\n");
    println!(
        "| subscriber | messages | rate (Hz) | seq gaps | latency p50 (ms) | p99 (ms) | max (ms) |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for (index, handle) in subscribers.into_iter().enumerate() {
        let (mut latencies, gaps, count) = handle.join().expect("subscriber");
        latencies.sort_by(f64::total_cmp);
        println!(
            "| {} | {count} | {:.1} | {gaps} | {:.3} | {:.3} | {:.3} |",
            index + 1,
            count as f64 / elapsed,
            percentile(&latencies, 0.5) * 1e3,
            percentile(&latencies, 0.99) * 1e3,
            latencies.last().copied().unwrap_or(f64::NAN) * 1e3
        );
    }
    round_trips.sort_by(f64::total_cmp);
    println!(
        "\nrobot-bridge CPU: {:.1}% of one core; instruction round trip p50 {:.3} ms, p99 {:.3} ms",
        cpu / elapsed * 100.0,
        percentile(&round_trips, 0.5) * 1e3,
        percentile(&round_trips, 0.99) * 1e3
    );
}
