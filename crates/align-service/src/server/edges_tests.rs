use std::time::Instant;

use super::*;
use crate::server::samples::TriggerQueue;

/// 125 Hz, a CB3's RTDE rate.
const PERIOD_S: f64 = 0.008;

/// A sample at tick `tick` of a joint moving at 0.5 rad/s, with the inputs `bits`.
fn sample(tick: u32, bits: Option<u64>) -> JointSample {
    let time_s = 10.0 + f64::from(tick) * PERIOD_S;
    JointSample {
        q: vec![0.5 * time_s, -1.0, 2.0 - time_s],
        qd: vec![0.5, 0.0, -1.0 + 0.01 * time_s],
        controller_time: time_s,
        received: Instant::now(),
        digital_inputs: bits,
    }
}

/// Feeds one sample per tick, the input high at the ticks `high` says, and returns the captures.
fn run(
    detector: &mut EdgeDetector,
    ticks: u32,
    high: impl Fn(u32) -> bool,
    bit: u64,
) -> Vec<TriggeredCapture> {
    (0..ticks)
        .filter_map(|tick| {
            let bits = if high(tick) { bit | 0b100 } else { 0b100 };
            detector.feed(&sample(tick, Some(bits)))
        })
        .collect()
}

#[test]
fn a_rise_between_two_samples_captures_the_interpolation_at_the_midpoint() {
    let input: DigitalInput = "CI3".parse().unwrap();
    let mut detector = EdgeDetector::new(input);
    let captures = run(&mut detector, 40, |tick| tick >= 20, 1 << 11);
    assert_eq!(captures.len(), 1, "{captures:?}");
    let capture = &captures[0];
    let (low, high) = (sample(19, None), sample(20, None));
    let edge_s = 0.5 * (low.controller_time + high.controller_time);
    assert!((capture.controller_time_s - edge_s).abs() < 1e-12);
    assert!((capture.time_uncertainty_s - PERIOD_S / 2.0).abs() < 1e-12);
    assert_eq!(capture.input, input);
    // Joints linear in time here, so the interpolation is exactly the motion at the edge time.
    let expected_q = [0.5 * edge_s, -1.0, 2.0 - edge_s];
    let expected_qd = [0.5, 0.0, -1.0 + 0.01 * edge_s];
    for (got, want) in capture.q.iter().zip(expected_q) {
        assert!((got - want).abs() < 1e-12, "{:?}", capture.q);
    }
    for (got, want) in capture.qd.iter().zip(expected_qd) {
        assert!((got - want).abs() < 1e-12, "{:?}", capture.qd);
    }
}

#[test]
fn an_input_already_high_at_the_start_is_not_an_edge_but_its_next_rise_is() {
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    let high_at_start = run(&mut detector, 10, |_| true, 1);
    assert!(high_at_start.is_empty());
    // Falls, stays low for 80 ms, rises: one capture.
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    let captures = run(&mut detector, 30, |tick| !(5..15).contains(&tick), 1);
    assert_eq!(captures.len(), 1);
    assert!((captures[0].controller_time_s - (10.0 + 14.5 * PERIOD_S)).abs() < 1e-12);
}

#[test]
fn a_chattering_input_captures_once_per_touch() {
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    // Low, then a touch that bounces (high, low, high, low, high) and a release that chatters
    // (low, high, low) before the input stays low; then a second clean touch.
    let pattern = |tick: u32| match tick {
        0..20 => false,
        20 | 22 | 24..60 => true,
        21 | 23 => false,
        60 | 62 => false,
        61 => true,
        63..80 => false,
        _ => true,
    };
    let captures = run(&mut detector, 100, pattern, 1);
    let times: Vec<f64> = captures.iter().map(|c| c.controller_time_s).collect();
    assert_eq!(captures.len(), 2, "{times:?}");
    assert!((times[0] - (10.0 + 19.5 * PERIOD_S)).abs() < 1e-12);
    assert!((times[1] - (10.0 + 79.5 * PERIOD_S)).abs() < 1e-12);
}

#[test]
fn other_inputs_gaps_and_unknown_inputs_capture_nothing() {
    // Another bit rising is not this input's edge.
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    assert!(run(&mut detector, 30, |tick| tick >= 15, 1 << 16).is_empty());
    // A rise across a gap of 200 ms in the stream.
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    let captures: Vec<_> = (0..10)
        .chain(35..40)
        .filter_map(|tick| detector.feed(&sample(tick, Some(u64::from(tick >= 35)))))
        .collect();
    assert!(captures.is_empty());
    // Samples without inputs in between: the low run starts again after them.
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    let captures: Vec<_> = (0..30)
        .filter_map(|tick| {
            let bits = match tick {
                0..10 => Some(0),
                10 => None,
                11..13 => Some(0),
                _ => Some(1),
            };
            detector.feed(&sample(tick, bits))
        })
        .collect();
    assert!(captures.is_empty(), "low for 16 ms only after the hole");
}

#[test]
fn a_controller_clock_restart_is_not_an_edge() {
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    let low: Vec<_> = (0..20)
        .filter_map(|tick| detector.feed(&sample(tick, Some(0))))
        .collect();
    assert!(low.is_empty());
    // The clock goes back: what follows is compared with nothing before it.
    assert!(detector.feed(&sample(3, Some(1))).is_none());
}

#[test]
fn the_queue_hands_captures_over_once() {
    let queue = TriggerQueue::default();
    let mut detector = EdgeDetector::new(DigitalInput::DI0);
    for capture in run(&mut detector, 40, |tick| tick >= 20, 1) {
        queue.push(capture);
    }
    assert_eq!(queue.take_all().len(), 1);
    assert!(queue.take_all().is_empty());
}
