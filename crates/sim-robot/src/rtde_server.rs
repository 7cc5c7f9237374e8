//! An RTDE server as a UR controller runs it on port 30004: protocol versions 1 and 2, the
//! controller version of the simulated model, output recipes with NOT_FOUND for unknown names,
//! data packages at the requested frequency clamped to the controller's maximum, several
//! clients at once. RTDE inputs (what a client writes) are not simulated: every input name is
//! answered NOT_FOUND. The controller's digital inputs are an output, `actual_digital_input_bits`,
//! where the probe's trigger shows.

use std::io::Write;
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use ur_rtde::{Package, ValueType, encode_value, output_type, package, recipe_names};

use crate::Shared;

/// One client's negotiated state.
struct Session {
    version: u16,
    types: Vec<ValueType>,
    names: Vec<String>,
    period: Duration,
}

pub(crate) fn serve(listener: TcpListener, shared: Arc<Shared>) {
    // Accept with a timeout so shutdown is noticed.
    let _ = listener.set_nonblocking(true);
    while !shared.shutdown.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let shared = Arc::clone(&shared);
                thread::spawn(move || client(stream, shared));
            }
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_millis(5));
            }
            Err(_) => thread::sleep(Duration::from_millis(50)),
        }
    }
}

fn client(stream: TcpStream, shared: Arc<Shared>) {
    let _ = stream.set_nodelay(true);
    let _ = stream.set_nonblocking(false);
    let Ok(mut writer) = stream.try_clone() else {
        return;
    };
    let mut reader = stream;
    let generation = shared.drop_generation.load(Ordering::Relaxed);
    let session = Arc::new(Mutex::new(Session {
        version: 1,
        types: Vec::new(),
        names: Vec::new(),
        period: Duration::from_secs_f64(1.0 / shared.max_frequency_hz),
    }));
    let streaming = Arc::new(AtomicBool::new(false));
    shared.clients.fetch_add(1, Ordering::Relaxed);
    let streamer = {
        let (shared, session, streaming) = (
            Arc::clone(&shared),
            Arc::clone(&session),
            Arc::clone(&streaming),
        );
        let Ok(out) = writer.try_clone() else {
            return;
        };
        thread::spawn(move || stream_data(out, shared, session, streaming, generation))
    };
    // Polling reads let the client notice a dropped-connection request.
    let _ = reader.set_read_timeout(Some(Duration::from_millis(50)));
    loop {
        if shared.shutdown.load(Ordering::Relaxed)
            || shared.drop_generation.load(Ordering::Relaxed) != generation
        {
            break;
        }
        let request = match Package::read_from(&mut reader) {
            Ok(request) => request,
            Err(ur_rtde::RtdeError::Io(error))
                if matches!(
                    error.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(_) => break,
        };
        // The streamer writes too: one write call per package under this lock keeps them
        // whole. Answering under the lock as well means that once a start request turns
        // streaming on, no data package can reach the client before the start reply (ur_rtde
        // reads exactly one package after its start request and takes it as the reply).
        let _guard = shared.write_lock.lock();
        let reply = answer(&request, &shared, &session, &streaming);
        if let Some(reply) = reply {
            let Ok(bytes) = reply.encode() else { break };
            if writer.write_all(&bytes).is_err() {
                break;
            }
        }
    }
    streaming.store(false, Ordering::Relaxed);
    let _ = reader.shutdown(std::net::Shutdown::Both);
    let _ = streamer.join();
    shared.clients.fetch_sub(1, Ordering::Relaxed);
}

fn answer(
    request: &Package,
    shared: &Shared,
    session: &Mutex<Session>,
    streaming: &AtomicBool,
) -> Option<Package> {
    let mut session = session
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    match request.kind {
        package::REQUEST_PROTOCOL_VERSION => {
            let asked = request
                .payload
                .get(..2)
                .map_or(0, |b| u16::from_be_bytes([b[0], b[1]]));
            let accepted = (1..=2).contains(&asked);
            if accepted {
                session.version = asked;
            }
            Some(Package::new(
                package::REQUEST_PROTOCOL_VERSION,
                vec![u8::from(accepted)],
            ))
        }
        package::GET_URCONTROL_VERSION => {
            let mut payload = Vec::new();
            for part in shared.controller_version {
                payload.extend_from_slice(&part.to_be_bytes());
            }
            Some(Package::new(package::GET_URCONTROL_VERSION, payload))
        }
        package::CONTROL_PACKAGE_SETUP_OUTPUTS => {
            let (frequency, names) = if session.version >= 2 {
                let frequency = request
                    .payload
                    .get(..8)
                    .map_or(shared.max_frequency_hz, |b| {
                        f64::from_be_bytes(b.try_into().unwrap_or([0; 8]))
                    });
                (frequency, request.payload.get(8..).unwrap_or_default())
            } else {
                (shared.max_frequency_hz, &request.payload[..])
            };
            let names: Vec<String> = recipe_names(&String::from_utf8_lossy(names))
                .into_iter()
                .map(str::to_owned)
                .collect();
            let types: Vec<Option<ValueType>> = names.iter().map(|n| output_type(n)).collect();
            let text = types
                .iter()
                .map(|t| t.map_or("NOT_FOUND", ValueType::name))
                .collect::<Vec<_>>()
                .join(",");
            let clamped = if frequency.is_finite() && frequency > 0.0 {
                frequency.min(shared.max_frequency_hz)
            } else {
                shared.max_frequency_hz
            };
            let complete = types.iter().all(Option::is_some);
            if complete {
                session.types = types.into_iter().flatten().collect();
                session.names = names;
                session.period = Duration::from_secs_f64(1.0 / clamped);
            }
            let mut payload = Vec::new();
            if session.version >= 2 {
                // Recipe id 0 marks a failed setup, as the controller does.
                payload.push(u8::from(complete));
            }
            payload.extend_from_slice(text.as_bytes());
            Some(Package::new(
                package::CONTROL_PACKAGE_SETUP_OUTPUTS,
                payload,
            ))
        }
        package::CONTROL_PACKAGE_SETUP_INPUTS => {
            let count = recipe_names(&String::from_utf8_lossy(&request.payload)).len();
            let mut payload = vec![0u8];
            payload.extend_from_slice(vec!["NOT_FOUND"; count].join(",").as_bytes());
            Some(Package::new(package::CONTROL_PACKAGE_SETUP_INPUTS, payload))
        }
        package::CONTROL_PACKAGE_START => {
            let ready = !session.types.is_empty();
            streaming.store(ready, Ordering::Relaxed);
            Some(Package::new(
                package::CONTROL_PACKAGE_START,
                vec![u8::from(ready)],
            ))
        }
        package::CONTROL_PACKAGE_PAUSE => {
            streaming.store(false, Ordering::Relaxed);
            Some(Package::new(package::CONTROL_PACKAGE_PAUSE, vec![1]))
        }
        _ => None,
    }
}

fn stream_data(
    mut out: TcpStream,
    shared: Arc<Shared>,
    session: Arc<Mutex<Session>>,
    streaming: Arc<AtomicBool>,
    generation: u64,
) {
    let mut next = Instant::now();
    loop {
        if shared.shutdown.load(Ordering::Relaxed)
            || shared.drop_generation.load(Ordering::Relaxed) != generation
        {
            return;
        }
        let period = session
            .lock()
            .map(|s| s.period)
            .unwrap_or(Duration::from_millis(8));
        next += period;
        let now = Instant::now();
        if next > now {
            thread::sleep(next - now);
        } else {
            next = now;
        }
        if !streaming.load(Ordering::Relaxed) || shared.paused.load(Ordering::Relaxed) {
            continue;
        }
        let bytes = {
            let session = session
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            let sample = shared.sample();
            let mut payload = Vec::new();
            if session.version >= 2 {
                payload.push(1);
            }
            for (name, kind) in session.names.iter().zip(&session.types) {
                encode_value(*kind, &sample.value(name), &mut payload);
            }
            Package::new(package::DATA_PACKAGE, payload).encode()
        };
        let Ok(bytes) = bytes else { return };
        let _guard = shared.write_lock.lock();
        if out.write_all(&bytes).is_err() {
            return;
        }
    }
}
