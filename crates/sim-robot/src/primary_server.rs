//! The primary interface a UR controller serves on port 30001, reduced to what the project reads
//! from it: a robot state message with the KINEMATICS_INFO sub-package (the calibrated DH table
//! the simulated controller really moves with) on connection and then ten times a second, as the
//! controller sends its robot state. Whatever a client sends is read and ignored (a real
//! controller would run it as URScript; the simulator runs none). `drop` on the control socket
//! closes these connections too.

use std::io::Read;
use std::net::{TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread;
use std::time::Duration;

use ur_primary::{Frame, KinematicsInfo, robot_state};

use crate::Shared;

/// How often the controller sends its robot state.
const STATE_PERIOD: Duration = Duration::from_millis(100);

pub(crate) fn serve(listener: TcpListener, shared: Arc<Shared>, kinematics: KinematicsInfo) {
    let message = robot_state(&[kinematics.to_frame()]);
    let _ = listener.set_nonblocking(true);
    while !shared.shutdown.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let shared = Arc::clone(&shared);
                let message = message.clone();
                thread::spawn(move || client(stream, shared, message));
            }
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_millis(5));
            }
            Err(_) => thread::sleep(Duration::from_millis(50)),
        }
    }
}

fn client(stream: TcpStream, shared: Arc<Shared>, message: Frame) {
    let _ = stream.set_nodelay(true);
    let _ = stream.set_nonblocking(false);
    let generation = shared.drop_generation.load(Ordering::Relaxed);
    let Ok(mut reader) = stream.try_clone() else {
        return;
    };
    // Drains what the client sends, so its writes never block; ends with the connection.
    let _ = reader.set_read_timeout(Some(Duration::from_millis(200)));
    let drain = thread::spawn(move || {
        let mut buffer = [0u8; 1024];
        loop {
            match reader.read(&mut buffer) {
                Ok(0) => return,
                Ok(_) => {}
                Err(error)
                    if matches!(
                        error.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(_) => return,
            }
        }
    });
    let mut writer = stream;
    while !shared.shutdown.load(Ordering::Relaxed)
        && shared.drop_generation.load(Ordering::Relaxed) == generation
    {
        if !shared.paused.load(Ordering::Relaxed) && message.write_to(&mut writer).is_err() {
            break;
        }
        thread::sleep(STATE_PERIOD);
    }
    let _ = writer.shutdown(std::net::Shutdown::Both);
    let _ = drain.join();
}
