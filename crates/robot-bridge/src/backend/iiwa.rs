//! KUKA LBR iiwa back end: an FRI monitoring client. It listens on a UDP port (30200 by
//! default) for the controller's monitoring messages, checks each one's identifier, answers every
//! `receive_multiplier`-th with a header-only command message that echoes the controller's
//! sequence counter (as the FRI client SDK does in monitoring mode), and turns the measured joint
//! positions into samples. FRI carries no joint velocities: they are differentiated from
//! consecutive positions over the controller's own time stamps, so the first message of a
//! session only seeds the difference and is not published.
//!
//! A receiver thread blocks on the socket and answers each message as it arrives (the answer's
//! timeliness is what the controller grades); it hands the messages over a channel, whose
//! timed wait is precise where a socket receive timeout only counts scheduler ticks (4 ms),
//! too coarse for a 1 ms controller.
//!
//! The controller counts as lost after three send periods without a message, and never sooner
//! than [`IiwaConfig::min_silence_ms`] (100 ms by default): the bridge runs on a host without a
//! real-time scheduler, where a stall of a few milliseconds is the host's, not a lost controller
//! (the messages it hid are still counted as missed by their sequence counter). A message after
//! that, or from a new session (its sequence counter started over), reconnects. Datagrams from
//! another host than `--robot-host`, and datagrams that are not LBR monitoring messages, are
//! counted and dropped.
//!
//! Digital inputs: FRI carries the IOs the Sunrise application registered for it (the monitor
//! data's `readIORequest`, by name). [`IiwaConfig::inputs`] names which of them to publish in
//! hwState's `digital_inputs` bit mask and as which bit (`Probe.Trigger=DI0`), so that a probe's
//! trigger reaches `ips serve --trigger` as a UR's does. A named IO the controller does not send,
//! or sends as an analog value, leaves `digital_inputs` out (unknown, not low) and is logged
//! once with the IOs it does send.

use std::net::{IpAddr, SocketAddr, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kuka_fri::{CommandMessage, MAX_MESSAGE_BYTES, MonitoringMessage, SessionState, encode};

use protocol::{DigitalInput, RobotSide};

use super::{Backend, BackendKind, BackendSettings, Event, LinkState, OpenError, Sample};

/// Send periods of silence after which the controller counts as lost.
pub const SILENT_PERIODS: u32 = 3;
/// The shortest silence that counts as a lost controller by default (ms), whatever the send
/// period: scheduler stalls on a loaded, non-real-time host reach tens of milliseconds.
pub const DEFAULT_MIN_SILENCE_MS: u64 = 100;
/// Assumed until the controller states its send period.
const DEFAULT_SEND_PERIOD: Duration = Duration::from_millis(5);
/// The UDP port Sunrise's FRI sends to by default.
pub const DEFAULT_FRI_PORT: u16 = 30200;

/// Where the iiwa's FRI messages come from and are received.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IiwaConfig {
    /// The controller's address; only its datagrams are accepted.
    pub robot_host: String,
    /// The UDP port to receive on; 0 picks a free one.
    pub fri_port: u16,
    /// FRI IOs to publish as digital inputs: each registered IO's name (`Group.Name`) and the
    /// hwState input it becomes.
    pub inputs: Vec<(String, DigitalInput)>,
    /// The shortest silence (ms) that counts as a lost controller; the limit is the longer of
    /// this and [`SILENT_PERIODS`] send periods.
    pub min_silence_ms: u64,
}

impl BackendSettings for IiwaConfig {
    fn kind(&self) -> BackendKind {
        BackendKind::Iiwa
    }

    fn robot_side(&self) -> RobotSide {
        RobotSide::IiwaDrive
    }

    fn open(&self) -> Result<Box<dyn Backend>, OpenError> {
        let mut backend = IiwaBackend::bind(&self.robot_host, self.fri_port).map_err(|source| {
            OpenError::FriListen {
                port: self.fri_port,
                source,
            }
        })?;
        backend.inputs = self.inputs.clone();
        backend.min_silence = Duration::from_millis(self.min_silence_ms);
        Ok(Box::new(backend))
    }
}

/// A monitoring message as the receiver thread got it.
struct Received {
    message: MonitoringMessage,
    peer: SocketAddr,
    at: Instant,
}

/// Datagrams the receiver dropped and why, the latest reason kept.
#[derive(Debug, Default)]
struct Rejections {
    count: u64,
    latest: Option<String>,
}

pub struct IiwaBackend {
    local_address: SocketAddr,
    messages: Receiver<Result<Received, String>>,
    rejections: Arc<Mutex<Rejections>>,
    stop: Arc<AtomicBool>,
    receiver: Option<JoinHandle<()>>,
    session: Option<Session>,
    announced_listening: bool,
    receiver_gone: bool,
    /// FRI IOs published as digital inputs ([`IiwaConfig::inputs`]).
    inputs: Vec<(String, DigitalInput)>,
    /// Why the inputs were last left out, logged once per reason.
    inputs_problem: Option<String>,
    /// The shortest silence that counts as a lost controller ([`IiwaConfig::min_silence_ms`]).
    min_silence: Duration,
}

/// The controller as last heard.
struct Session {
    send_period: Duration,
    last_message: Instant,
    /// Sequence counter, time stamp (s) and positions of the previous message.
    previous: Option<(u32, f64, Vec<f64>)>,
}

impl std::fmt::Debug for IiwaBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IiwaBackend")
            .field("local_address", &self.local_address)
            .finish()
    }
}

impl IiwaBackend {
    /// Binds the FRI port (0 picks a free one) and starts answering. `robot_host` is the
    /// controller's address; only its datagrams are accepted.
    pub fn bind(robot_host: &str, port: u16) -> std::io::Result<Self> {
        let controller_ip = (robot_host, 0)
            .to_socket_addrs()?
            .next()
            .map(|address| address.ip());
        let socket = UdpSocket::bind(("0.0.0.0", port))?;
        let local_address = socket.local_addr()?;
        // Only so that shutdown is noticed; messages wake the thread at once.
        socket.set_read_timeout(Some(Duration::from_millis(100)))?;
        let (sender, messages) = mpsc::channel();
        let rejections = Arc::new(Mutex::new(Rejections::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let receiver = {
            let (rejections, stop) = (Arc::clone(&rejections), Arc::clone(&stop));
            std::thread::spawn(move || receive(&socket, controller_ip, &sender, &rejections, &stop))
        };
        Ok(Self {
            local_address,
            messages,
            rejections,
            stop,
            receiver: Some(receiver),
            session: None,
            announced_listening: false,
            receiver_gone: false,
            inputs: Vec::new(),
            inputs_problem: None,
            min_silence: Duration::from_millis(DEFAULT_MIN_SILENCE_MS),
        })
    }

    /// The bound UDP address.
    pub fn local_address(&self) -> SocketAddr {
        self.local_address
    }

    /// Turns one monitoring message into an event: the first of a session connects, the others
    /// are samples.
    fn on_message(&mut self, received: Received) -> Option<Event> {
        let Received { message, peer, at } = received;
        let sequence = message.header.sequence_counter;
        let send_period = message
            .send_period_s()
            .map_or(DEFAULT_SEND_PERIOD, Duration::from_secs_f64);
        let (Some(positions), Some(time_s)) =
            (message.measured_positions(), message.controller_time_s())
        else {
            reject(
                &self.rejections,
                format!("from {peer}: a monitoring message without positions or time stamp"),
            );
            return None;
        };
        let positions = positions.to_vec();
        let link = LinkState {
            session_state: message.session_state().map(SessionState::name),
            quality: message.quality().map(kuka_fri::ConnectionQuality::name),
        };
        let new_session = match &self.session {
            None => true,
            // A counter that went back (other than by wrapping) is a new FRI session.
            Some(session) => session
                .previous
                .as_ref()
                .is_some_and(|(previous, _, _)| sequence.wrapping_sub(*previous) > u32::MAX / 2),
        };
        if new_session {
            let registered: Vec<&str> =
                message.monitor_data.as_ref().map_or_else(Vec::new, |data| {
                    data.read_io_request
                        .iter()
                        .map(|io| io.name.as_str())
                        .collect()
                });
            // Which IOs the application registered: what a probe that never triggers needs.
            let description = format!(
                "FRI from {peer}, send period {} ms, answering every {} message(s), session {}, IOs for FRI: {}",
                send_period.as_millis(),
                message.receive_multiplier(),
                link.session_state.unwrap_or("unknown"),
                if registered.is_empty() {
                    "none".to_owned()
                } else {
                    registered.join(", ")
                }
            );
            self.session = Some(Session {
                send_period,
                last_message: at,
                previous: Some((sequence, time_s, positions)),
            });
            return Some(Event::Connected { description });
        }
        let session = self.session.as_mut()?;
        session.send_period = send_period;
        session.last_message = at;
        let previous = session
            .previous
            .replace((sequence, time_s, positions.clone()));
        let (_, previous_time_s, previous_positions) = previous?;
        let dt_s = time_s - previous_time_s;
        if dt_s <= 0.0 || previous_positions.len() != positions.len() {
            // A repeated or reordered datagram: nothing to differentiate, nothing new.
            return None;
        }
        let velocity = positions
            .iter()
            .zip(&previous_positions)
            .map(|(q, q_previous)| (q - q_previous) / dt_s)
            .collect();
        let effort = message
            .measured_torques()
            .filter(|torques| torques.len() == positions.len())
            .map(<[f64]>::to_vec);
        Some(Event::Sample(Sample {
            position: positions,
            velocity,
            effort,
            controller_time: time_s,
            controller_seq: Some(u64::from(sequence)),
            robot_mode: message.session_state().map(|state| state as i32),
            safety_mode: message
                .robot_info
                .as_ref()
                .and_then(|info| info.safety_state),
            link: Some(link),
            digital_inputs: self.digital_inputs(&message),
        }))
    }

    /// The configured FRI IOs as hwState's bit mask; `None` when none are configured, or one is
    /// missing from the message or not a switch (logged once with the IOs the message has).
    fn digital_inputs(&mut self, message: &MonitoringMessage) -> Option<u64> {
        if self.inputs.is_empty() {
            return None;
        }
        let registered = message
            .monitor_data
            .as_ref()
            .map_or(&[][..], |data| &data.read_io_request[..]);
        let mut bits = 0;
        let mut problem = None;
        for (name, input) in &self.inputs {
            match registered.iter().find(|io| &io.name == name) {
                Some(io) => match io.is_set() {
                    Some(true) => bits |= input.mask(),
                    Some(false) => {}
                    None => problem = Some(format!("FRI IO '{name}' is analog or has no value")),
                },
                None => problem = Some(format!("the controller sends no FRI IO '{name}'")),
            }
        }
        match problem {
            None => {
                self.inputs_problem = None;
                Some(bits)
            }
            Some(problem) => {
                if self.inputs_problem.as_ref() != Some(&problem) {
                    let names: Vec<&str> = registered.iter().map(|io| io.name.as_str()).collect();
                    tracing::warn!(
                        %problem,
                        registered = ?names,
                        "digital inputs left out of hwState: register the IO for FRI in the Sunrise application (registerIO) and name it as the controller does"
                    );
                    self.inputs_problem = Some(problem);
                }
                None
            }
        }
    }
}

impl Drop for IiwaBackend {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(receiver) = self.receiver.take() {
            let _ = receiver.join();
        }
    }
}

fn reject(rejections: &Mutex<Rejections>, reason: String) {
    let mut rejections = rejections.lock().unwrap_or_else(|p| p.into_inner());
    rejections.count += 1;
    rejections.latest = Some(reason);
}

/// The receiver thread: checks each datagram, answers every `receive_multiplier`-th monitoring
/// message with a header-only command message, and passes the messages on.
fn receive(
    socket: &UdpSocket,
    controller_ip: Option<IpAddr>,
    messages: &Sender<Result<Received, String>>,
    rejections: &Mutex<Rejections>,
    stop: &AtomicBool,
) {
    let mut buffer = [0u8; MAX_MESSAGE_BYTES + 1];
    let mut own_sequence: u32 = 0;
    let mut received_since_answer: u32 = 0;
    while !stop.load(Ordering::Relaxed) {
        let (count, peer) = match socket.recv_from(&mut buffer) {
            Ok(received) => received,
            Err(error)
                if matches!(
                    error.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(error) => {
                let _ = messages.send(Err(format!("FRI socket error: {error}")));
                return;
            }
        };
        let at = Instant::now();
        if controller_ip.is_some_and(|ip| ip != peer.ip()) {
            reject(
                rejections,
                format!("a datagram from {peer}, not the controller"),
            );
            continue;
        }
        let message = match MonitoringMessage::decode_checked(&buffer[..count]) {
            Ok(message) => message,
            Err(error) => {
                reject(rejections, format!("from {peer}: {error}"));
                continue;
            }
        };
        received_since_answer += 1;
        if received_since_answer >= message.receive_multiplier() {
            received_since_answer = 0;
            let reply =
                CommandMessage::monitoring_reply(own_sequence, message.header.sequence_counter);
            own_sequence = own_sequence.wrapping_add(1);
            let _ = socket.send_to(&encode(&reply), peer);
        }
        if messages.send(Ok(Received { message, peer, at })).is_err() {
            return;
        }
    }
}

impl Backend for IiwaBackend {
    fn joint_names(&self) -> Vec<String> {
        (1..=kuka_fri::LBR_JOINTS)
            .map(|joint| format!("iiwa_joint_{joint}"))
            .collect()
    }

    fn effort_unit(&self) -> Option<&'static str> {
        Some("N m")
    }

    fn next_event(&mut self, timeout: Duration) -> Option<Event> {
        if !self.announced_listening {
            self.announced_listening = true;
            return Some(Event::Connecting);
        }
        if self.receiver_gone {
            std::thread::sleep(timeout);
            return None;
        }
        let started = Instant::now();
        loop {
            let now = Instant::now();
            let mut wait = timeout.saturating_sub(now - started);
            if let Some(session) = &self.session {
                let silence_limit = (session.send_period * SILENT_PERIODS).max(self.min_silence);
                let silent = now.saturating_duration_since(session.last_message);
                if silent >= silence_limit {
                    let period_ms = session.send_period.as_secs_f64() * 1e3;
                    self.session = None;
                    return Some(Event::Lost {
                        reason: format!(
                            "no FRI message for {:.1} ms (limit {} ms: the longer of {SILENT_PERIODS} send periods of {period_ms} ms and {} ms)",
                            silent.as_secs_f64() * 1e3,
                            silence_limit.as_millis(),
                            self.min_silence.as_millis()
                        ),
                    });
                }
                wait = wait.min(silence_limit - silent);
            }
            if wait.is_zero() {
                return None;
            }
            match self.messages.recv_timeout(wait) {
                Ok(Ok(received)) => {
                    if let Some(event) = self.on_message(received) {
                        return Some(event);
                    }
                }
                Ok(Err(reason)) => {
                    self.receiver_gone = true;
                    self.session = None;
                    return Some(Event::Lost { reason });
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    self.receiver_gone = true;
                    self.session = None;
                    return Some(Event::Lost {
                        reason: "the FRI receiver stopped".to_owned(),
                    });
                }
            }
        }
    }

    fn controller_endpoint(&self) -> Option<String> {
        Some(format!("udp://{}", self.local_address))
    }

    fn rejected_datagrams(&self) -> Option<(u64, Option<String>)> {
        let rejections = self.rejections.lock().unwrap_or_else(|p| p.into_inner());
        Some((rejections.count, rejections.latest.clone()))
    }
}
