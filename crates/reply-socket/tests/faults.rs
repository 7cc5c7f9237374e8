//! What stopped plain REP sockets: multipart requests and raw TCP garbage. After each, a REQ
//! client is still answered.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use reply_socket::{ReplySocket, Wait};

/// Serves "echo: FRAME" (or the refusal) until `stop`.
fn echo_server(stop: Arc<AtomicBool>) -> (String, std::thread::JoinHandle<()>) {
    let context = zmq::Context::new();
    let (socket, endpoint) = ReplySocket::bind(&context, "tcp://127.0.0.1:*", 50).unwrap();
    let thread = std::thread::spawn(move || {
        let _context = context;
        while !stop.load(Ordering::Relaxed) {
            if let Wait::Request(request) = socket.receive() {
                let reply = match request.single_frame(64) {
                    Ok(frame) => format!("echo: {}", String::from_utf8_lossy(frame)),
                    Err(reason) => format!("refused: {reason}"),
                };
                let _ = socket.reply(&request, reply.as_bytes());
            }
        }
    });
    (endpoint, thread)
}

fn client(context: &zmq::Context, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(5_000).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

fn ask(socket: &zmq::Socket, frames: &[&[u8]]) -> String {
    socket.send_multipart(frames.iter().copied(), 0).unwrap();
    socket.recv_string(0).unwrap().unwrap()
}

#[test]
fn multipart_empty_and_oversized_requests_are_refused_and_the_client_goes_on() {
    let stop = Arc::new(AtomicBool::new(false));
    let (endpoint, server) = echo_server(Arc::clone(&stop));
    let context = zmq::Context::new();
    let socket = client(&context, &endpoint);
    assert!(ask(&socket, &[b"status", b"junk"]).contains("multipart request of 2 frames"));
    assert!(ask(&socket, &[b""]).starts_with("echo: "));
    assert!(ask(&socket, &[&[b'x'; 65]]).contains("65 bytes exceeds the 64-byte limit"));
    assert_eq!(ask(&socket, &[b"status"]), "echo: status");
    stop.store(true, Ordering::Relaxed);
    server.join().unwrap();
}

#[test]
fn raw_tcp_garbage_does_not_stop_other_clients_being_answered() {
    let stop = Arc::new(AtomicBool::new(false));
    let (endpoint, server) = echo_server(Arc::clone(&stop));
    let address = endpoint.trim_start_matches("tcp://").to_owned();
    let context = zmq::Context::new();
    // Deterministic garbage: some of it starts like a ZMTP greeting, some not at all.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for variant in 0..8 {
        let mut bytes = Vec::new();
        if variant % 2 == 0 {
            bytes.extend_from_slice(&[0xFF, 0, 0, 0, 0, 0, 0, 0, 1, 0x7F]);
        }
        for _ in 0..(64 + 97 * variant) {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            bytes.push((state >> 24) as u8);
        }
        let mut garbage = std::net::TcpStream::connect(&address).unwrap();
        let _ = garbage.write_all(&bytes);
        let socket = client(&context, &endpoint);
        assert_eq!(
            ask(&socket, &[b"status"]),
            "echo: status",
            "variant {variant}"
        );
        drop(garbage);
        let after = client(&context, &endpoint);
        assert_eq!(ask(&after, &[b"again"]), "echo: again", "variant {variant}");
    }
    stop.store(true, Ordering::Relaxed);
    server.join().unwrap();
}
