//! The robot moving live on the twin: a subscriber to robot-bridge's hardware-state stream (the
//! same PUB the service mirrors from), in a thread of its own, turning each sample into the
//! robot's joint positions and TCP by forward kinematics on the server.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use crate::scene::LiveRobot;
use crate::state::Shared;

/// Samples closer together than this are not all turned into poses: the page redraws at most
/// this often (the bridge publishes at 125-200 Hz).
const MIN_PERIOD: Duration = Duration::from_millis(40);

/// Subscribes to `bridge_pub` until `stop`; publishes each pose on `shared.robot`.
pub fn spawn(
    bridge_pub: &str,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<()>, zmq::Error> {
    let context = zmq::Context::new();
    let sub = context.socket(zmq::SUB)?;
    sub.set_linger(0)?;
    // The stop flag is looked at between receives.
    sub.set_rcvtimeo(100)?;
    sub.set_subscribe(b"")?;
    sub.connect(bridge_pub)?;
    Ok(thread::spawn(move || {
        // The context must outlive its socket: both move here.
        let _context = context;
        let mut last_sent: Option<Instant> = None;
        while !stop.load(Ordering::Relaxed) {
            let Ok(bytes) = sub.recv_bytes(0) else {
                continue;
            };
            if last_sent.is_some_and(|at| at.elapsed() < MIN_PERIOD) {
                continue;
            }
            let Ok(message) = serde_json::from_slice::<protocol::HwState>(&bytes) else {
                continue;
            };
            let body = message.body;
            let Some(pose) = shared.scene.robot_pose(&body.position) else {
                continue;
            };
            last_sent = Some(Instant::now());
            shared.robot.send_replace(Some(LiveRobot {
                pose,
                q: body.position,
                controller_time_s: body.controller_time,
            }));
        }
    }))
}
