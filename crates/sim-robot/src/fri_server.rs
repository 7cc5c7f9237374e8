//! The controller side of KUKA FRI as a Sunrise cabinet runs it for a monitoring session: a
//! monitoring message to the client every send period (1-100 ms), the client's header-only
//! answers graded for timeliness, and the session state following the connection quality.
//!
//! Grading (our emulator's rule; KUKA does not publish its thresholds): the client is expected
//! to answer one message in every `receive_multiplier`; an answer is timely when it reflects one
//! of the last `receive_multiplier` messages sent. Over the last [`WINDOW`] messages the share of
//! expected answers that came in time gives the quality: at least 98% EXCELLENT, 90% GOOD,
//! 60% FAIR, else POOR. The session is MONITORING_READY from GOOD upwards and stays so down to
//! FAIR; at POOR it falls back to MONITORING_WAIT, where a new session also starts.

use std::collections::VecDeque;
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use kuka_fri::{
    CommandMessage, ConnectionInfo, ConnectionQuality, ControlMode, DriveState, FriIoValue,
    JointValues, LBR_JOINTS, MAX_MESSAGE_BYTES, MONITORING_MESSAGE_ID, MessageHeader,
    MessageMonitorData, MonitoringMessage, OperationMode, RobotInfo, SafetyState, SessionState,
    TimeStamp, encode,
};

use crate::{Sample, Shared};

/// Messages over which the connection quality is graded.
pub(crate) const WINDOW: usize = 100;

/// What the control socket reports about the FRI link.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LinkReport {
    pub(crate) session_state: SessionState,
    pub(crate) quality: ConnectionQuality,
    pub(crate) sequence: u32,
    pub(crate) timely_answers: u64,
    pub(crate) local_address: String,
}

/// Timeliness of the client's answers over the last [`WINDOW`] messages.
#[derive(Debug)]
pub(crate) struct LinkGrader {
    receive_multiplier: u32,
    /// One entry per message sent, oldest first: its sequence counter and whether it was
    /// answered in time.
    sent: VecDeque<(u32, bool)>,
    session_state: SessionState,
}

impl LinkGrader {
    pub(crate) fn new(receive_multiplier: u32) -> Self {
        Self {
            receive_multiplier: receive_multiplier.max(1),
            sent: VecDeque::with_capacity(WINDOW + 1),
            session_state: SessionState::MonitoringWait,
        }
    }

    pub(crate) fn on_sent(&mut self, sequence: u32) {
        self.sent.push_back((sequence, false));
        while self.sent.len() > WINDOW {
            self.sent.pop_front();
        }
    }

    /// Records an answer; returns whether it was timely.
    pub(crate) fn on_answer(&mut self, reflected: u32) -> bool {
        let recent = self.sent.len().min(self.receive_multiplier as usize);
        let start = self.sent.len() - recent;
        match self
            .sent
            .range_mut(start..)
            .find(|(seq, _)| *seq == reflected)
        {
            Some(entry) => {
                entry.1 = true;
                true
            }
            None => false,
        }
    }

    pub(crate) fn quality(&self) -> ConnectionQuality {
        let multiplier = self.receive_multiplier as usize;
        // The newest messages may still be answered: grade only those whose time is up.
        let graded = self.sent.len().saturating_sub(multiplier);
        let expected = graded / multiplier;
        if expected < 10 {
            return ConnectionQuality::Poor;
        }
        let answered = self
            .sent
            .iter()
            .take(graded)
            .filter(|(_, timely)| *timely)
            .count();
        let share = answered.min(expected) as f64 / expected as f64;
        if share >= 0.98 {
            ConnectionQuality::Excellent
        } else if share >= 0.9 {
            ConnectionQuality::Good
        } else if share >= 0.6 {
            ConnectionQuality::Fair
        } else {
            ConnectionQuality::Poor
        }
    }

    /// Advances the session state machine on the current quality.
    pub(crate) fn session_state(&mut self) -> SessionState {
        let quality = self.quality();
        self.session_state = match (self.session_state, quality) {
            (_, ConnectionQuality::Poor) => SessionState::MonitoringWait,
            (SessionState::MonitoringReady, _) => SessionState::MonitoringReady,
            (_, ConnectionQuality::Good | ConnectionQuality::Excellent) => {
                SessionState::MonitoringReady
            }
            (state, ConnectionQuality::Fair) => state,
        };
        self.session_state
    }
}

/// How the emulator talks FRI.
#[derive(Debug, Clone)]
pub(crate) struct FriLink {
    pub(crate) target: SocketAddr,
    pub(crate) send_period: Duration,
    pub(crate) receive_multiplier: u32,
    /// The boolean input carrying the probe's trigger, when the emulated application
    /// registered one for FRI.
    pub(crate) trigger_io: Option<String>,
}

fn monitoring_message(
    sequence: u32,
    reflected: u32,
    sample: &Sample,
    session_state: SessionState,
    quality: ConnectionQuality,
    link: &FriLink,
) -> MonitoringMessage {
    let (time_s, q) = (sample.time_s, &sample.q);
    let whole_s = time_s.floor();
    MonitoringMessage {
        header: MessageHeader {
            message_identifier: MONITORING_MESSAGE_ID,
            sequence_counter: sequence,
            reflected_sequence_counter: reflected,
        },
        robot_info: Some(RobotInfo {
            number_of_joints: Some(LBR_JOINTS as i32),
            safety_state: Some(SafetyState::NormalOperation as i32),
            drive_state: vec![DriveState::Active as i32; LBR_JOINTS],
            operation_mode: Some(OperationMode::TestMode1 as i32),
            control_mode: Some(ControlMode::PositionControl as i32),
        }),
        monitor_data: Some(MessageMonitorData {
            measured_joint_position: Some(JointValues { value: q.to_vec() }),
            // The simulator has no dynamics: it reports no torques rather than invented ones.
            read_io_request: (link.trigger_io.iter())
                .map(|name| FriIoValue::boolean_input(name, sample.digital_inputs != 0))
                .collect(),
            timestamp: Some(TimeStamp {
                sec: whole_s as u32,
                nanosec: ((time_s - whole_s) * 1e9).round().min(999_999_999.0) as u32,
            }),
            ..MessageMonitorData::default()
        }),
        connection_info: Some(ConnectionInfo {
            session_state: session_state as i32,
            quality: quality as i32,
            send_period_ms: Some(link.send_period.as_millis() as u32),
            receive_multiplier: Some(link.receive_multiplier),
        }),
        end_of_message_data: None,
    }
}

/// Sends monitoring messages to `link.target` from `socket` until shutdown. A `drop` request
/// closes the session: a new socket (new source port), counters from zero, grading anew.
///
/// Pacing uses `thread::sleep` (a high-resolution timer) and the socket is non-blocking:
/// socket receive timeouts count in scheduler ticks (4 ms at 250 Hz) and cannot keep a 1 ms
/// period. Answers are collected just before each send, which is exactly the controller's
/// deadline for them.
pub(crate) fn serve(mut socket: UdpSocket, link: FriLink, shared: Arc<Shared>) {
    let _ = socket.set_nonblocking(true);
    let mut grader = LinkGrader::new(link.receive_multiplier);
    let mut sequence: u32 = 0;
    let mut reflected: u32 = 0;
    let mut generation = shared.drop_generation.load(Ordering::Relaxed);
    let mut next_send = Instant::now();
    let mut buffer = [0u8; MAX_MESSAGE_BYTES + 1];
    while !shared.shutdown.load(Ordering::Relaxed) {
        let current = shared.drop_generation.load(Ordering::Relaxed);
        if current != generation {
            generation = current;
            let local = socket.local_addr().map_or_else(
                |_| SocketAddr::from(([0, 0, 0, 0], 0)),
                |a| SocketAddr::new(a.ip(), 0),
            );
            if let Ok(fresh) = UdpSocket::bind(local) {
                let _ = fresh.set_nonblocking(true);
                socket = fresh;
            }
            grader = LinkGrader::new(link.receive_multiplier);
            sequence = 0;
            reflected = 0;
        }
        let wait = next_send.saturating_duration_since(Instant::now());
        if !wait.is_zero() {
            std::thread::sleep(wait);
        }
        next_send += link.send_period;
        let now = Instant::now();
        if next_send < now {
            // Fell behind (the machine stalled): keep the period, skip the missed slots.
            next_send = now + link.send_period;
        }
        while let Ok((count, from)) = socket.recv_from(&mut buffer) {
            if from.ip() != link.target.ip() && !link.target.ip().is_unspecified() {
                continue;
            }
            if let Ok(answer) = CommandMessage::decode_checked(&buffer[..count]) {
                if grader.on_answer(answer.header.reflected_sequence_counter) {
                    let mut report = shared.fri.lock().unwrap_or_else(|p| p.into_inner());
                    if let Some(report) = report.as_mut() {
                        report.timely_answers += 1;
                    }
                }
                reflected = answer.header.sequence_counter;
            }
        }
        if !shared.paused.load(Ordering::Relaxed) {
            let sample = shared.sample();
            let state = grader.session_state();
            let message =
                monitoring_message(sequence, reflected, &sample, state, grader.quality(), &link);
            let _ = socket.send_to(&encode(&message), link.target);
            grader.on_sent(sequence);
            sequence = sequence.wrapping_add(1);
        }
        publish_report(&shared, &grader, sequence, &socket);
    }
}

fn publish_report(shared: &Shared, grader: &LinkGrader, sequence: u32, socket: &UdpSocket) {
    let mut report = shared.fri.lock().unwrap_or_else(|p| p.into_inner());
    let timely_answers = report.as_ref().map_or(0, |r| r.timely_answers);
    *report = Some(LinkReport {
        session_state: grader.session_state,
        quality: grader.quality(),
        sequence,
        timely_answers,
        local_address: socket
            .local_addr()
            .map(|a| a.to_string())
            .unwrap_or_default(),
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_follows_the_share_of_timely_answers() {
        let mut grader = LinkGrader::new(1);
        assert_eq!(grader.quality(), ConnectionQuality::Poor);
        for seq in 0..100 {
            grader.on_sent(seq);
            assert!(grader.on_answer(seq));
        }
        assert_eq!(grader.quality(), ConnectionQuality::Excellent);
        assert_eq!(grader.session_state(), SessionState::MonitoringReady);
        // Every fourth answer missing: 75% -> FAIR, the session stays ready.
        for seq in 100..200 {
            grader.on_sent(seq);
            if seq % 4 != 0 {
                grader.on_answer(seq);
            }
        }
        assert_eq!(grader.quality(), ConnectionQuality::Fair);
        assert_eq!(grader.session_state(), SessionState::MonitoringReady);
        // No answers: POOR, back to waiting.
        for seq in 200..300 {
            grader.on_sent(seq);
        }
        assert_eq!(grader.quality(), ConnectionQuality::Poor);
        assert_eq!(grader.session_state(), SessionState::MonitoringWait);
    }

    #[test]
    fn late_answers_do_not_count() {
        let mut grader = LinkGrader::new(2);
        grader.on_sent(0);
        grader.on_sent(1);
        grader.on_sent(2);
        assert!(!grader.on_answer(0), "two messages later is too late");
        assert!(grader.on_answer(1));
    }

    #[test]
    fn with_a_receive_multiplier_one_answer_in_n_is_enough() {
        let mut grader = LinkGrader::new(5);
        for seq in 0..100 {
            grader.on_sent(seq);
            if seq % 5 == 4 {
                grader.on_answer(seq);
            }
        }
        assert_eq!(grader.quality(), ConnectionQuality::Excellent);
    }
}
