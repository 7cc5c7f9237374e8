//! The operator's page behind `ips serve --http ADDR` (DESIGN.md 6.6): an HTTP server that is a
//! client of the alignment service's REP socket, never a second copy of it.
//!
//! - [`service_link`]: the one REQ socket to the service, in a thread of its own; the page's
//!   commands are the typed `ServiceCommand`s `ips` sends, so the service validates them alike;
//! - [`state`]: status and inspections polled from the service every 200 ms, published on change;
//! - [`events`]: server-sent events carrying them (and the live robot) to every open page;
//! - [`live`]: the bridge's hardware-state stream turned into robot poses for the twin;
//! - [`scene`]: the session's part mesh, nominal pose and kinematics, loaded when the page starts,
//!   and [`robot_shapes`]: the robot's URDF visual primitives posed at each joint sample;
//! - [`api`], [`assets`]: the JSON endpoints and the embedded page (HTML, JS, CSS, three.js).
//!
//! The server runs on a tokio runtime in a thread of its own, beside the service's threads;
//! [`start`] binds the address first, so a test binds `127.0.0.1:0` and reads the port back.

pub mod api;
pub mod assets;
pub mod events;
pub mod live;
pub mod robot_shapes;
pub mod scene;
pub mod service_link;
pub mod state;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::Response;
use axum::routing::{get, post};
use tokio::sync::oneshot;

use crate::scene::Scene;
use crate::service_link::ServiceLink;
use crate::state::Shared;

/// Where the page listens and what it talks to.
#[derive(Debug, Clone)]
pub struct Config {
    /// `HOST:PORT` to bind, e.g. `127.0.0.1:8080` (`127.0.0.1:0` picks a free port).
    pub listen: String,
    /// The service's REP endpoint as bound (a wildcard address is reached on loopback).
    pub service: String,
    /// robot-bridge's instruction REP endpoint, as the service uses it (shown on the page).
    pub bridge_rep: String,
    /// robot-bridge's hardware-state PUB endpoint, for the live robot.
    pub bridge_pub: String,
    /// The session file the service loaded: the twin's part and robot.
    pub session: PathBuf,
    /// How long the page waits for one reply from the service.
    pub reply_timeout: Duration,
}

/// Why the page could not start.
#[derive(Debug, thiserror::Error)]
pub enum PageError {
    #[error("operator page: cannot listen on '{listen}': {source}")]
    Bind {
        listen: String,
        source: std::io::Error,
    },
    #[error("operator page: {0}")]
    Session(#[from] align_service::BadInput),
    #[error("operator page: bridge stream {endpoint}: {source}")]
    Bridge {
        endpoint: String,
        source: zmq::Error,
    },
    #[error("operator page: cannot start its runtime: {0}")]
    Runtime(std::io::Error),
}

/// A running page.
#[derive(Debug)]
pub struct Handle {
    pub local_addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    live_stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Handle {
    /// `http://HOST:PORT` as the READY line names it.
    pub fn url(&self) -> String {
        format!("http://{}", self.local_addr)
    }

    /// Stops serving (open event streams are cut) and waits for the threads.
    pub fn stop(mut self) {
        self.signal_stop();
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }

    fn signal_stop(&mut self) {
        self.live_stop.store(true, Ordering::Relaxed);
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}

impl Drop for Handle {
    fn drop(&mut self) {
        self.signal_stop();
    }
}

/// Binds `config.listen`, loads the session's scene and serves until [`Handle::stop`].
pub fn start(config: &Config) -> Result<Handle, PageError> {
    let scene = Scene::load(&config.session)?;
    let bind_error = |source| PageError::Bind {
        listen: config.listen.clone(),
        source,
    };
    let listener = std::net::TcpListener::bind(&config.listen).map_err(bind_error)?;
    listener.set_nonblocking(true).map_err(bind_error)?;
    let local_addr = listener.local_addr().map_err(bind_error)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("operator-page")
        .enable_all()
        .build()
        .map_err(PageError::Runtime)?;
    let link = ServiceLink::connect(
        &service_link::local_endpoint(&config.service),
        config.reply_timeout,
    );
    let endpoints = state::Endpoints {
        service: config.service.clone(),
        bridge_rep: config.bridge_rep.clone(),
        bridge_pub: config.bridge_pub.clone(),
    };
    let shared = Arc::new(Shared::new(link, scene, endpoints));
    let live_stop = Arc::new(AtomicBool::new(false));
    let live = live::spawn(
        &config.bridge_pub,
        Arc::clone(&shared),
        Arc::clone(&live_stop),
    )
    .map_err(|source| PageError::Bridge {
        endpoint: config.bridge_pub.clone(),
        source,
    })?;
    let (stop, stopped) = oneshot::channel();
    let server = thread::spawn(move || {
        runtime.block_on(async move {
            let listener = match tokio::net::TcpListener::from_std(listener) {
                Ok(listener) => listener,
                Err(error) => {
                    tracing::error!(%error, "operator page: the listener cannot be used");
                    return;
                }
            };
            tokio::spawn(state::poll(Arc::clone(&shared)));
            let serve = axum::serve(listener, router(shared));
            tokio::select! {
                result = serve => {
                    if let Err(error) = result {
                        tracing::error!(%error, "operator page stopped");
                    }
                }
                _ = stopped => {}
            }
        });
        // Event streams never end by themselves: their tasks are dropped here.
        runtime.shutdown_timeout(Duration::from_millis(500));
    });
    Ok(Handle {
        local_addr,
        stop: Some(stop),
        live_stop,
        threads: vec![server, live],
    })
}

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(assets::index))
        .route("/page.js", get(assets::page_js))
        .route("/twin.js", get(assets::twin_js))
        .route("/page.css", get(assets::page_css))
        .route("/vendor/three.module.min.js", get(assets::three_js))
        .route("/vendor/three.LICENSE", get(assets::three_license))
        .route("/api/state", get(api::state))
        .route("/api/scene", get(api::scene))
        .route("/api/events", get(events::stream))
        .route("/api/command", post(command))
        .fallback(|| async { api::refusal(StatusCode::NOT_FOUND, "no such page or endpoint") })
        .with_state(shared)
}

/// Whether a `Host` header names this server by IP address or as localhost. A name that could
/// be any other (DNS rebinding: a web site whose name suddenly resolves to 127.0.0.1) is not
/// trusted with commands, since the browser would then treat the page's origin as that site's.
fn trusted_host(host: &str) -> bool {
    let name = match host.rsplit_once(':') {
        // `[::1]:8080`, `127.0.0.1:8080`, `localhost:8080`; a bare IPv6 literal has colons too.
        Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) && !name.is_empty() => name,
        _ => host,
    };
    let name = name
        .strip_prefix('[')
        .and_then(|n| n.strip_suffix(']'))
        .unwrap_or(name);
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok()
}

/// `POST /api/command`, after the checks on the body itself: JSON only (a browser sends a
/// cross-site JSON post only after a preflight this server never grants, so another site the
/// operator visits cannot press the page's buttons), at most [`api::MAX_COMMAND_BYTES`].
async fn command(State(shared): State<Arc<Shared>>, headers: HeaderMap, body: Body) -> Response {
    let host = headers
        .get(header::HOST)
        .and_then(|value| value.to_str().ok())
        .unwrap_or_default();
    if !trusted_host(host) {
        return api::refusal(
            StatusCode::FORBIDDEN,
            format!(
                "commands are taken only from the page opened by IP address or localhost, not '{host}'"
            ),
        );
    }
    let json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|value| value.to_str().ok())
        .is_some_and(|value| value.starts_with("application/json"));
    if !json {
        return api::refusal(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "send the command as Content-Type: application/json",
        );
    }
    let Ok(bytes) = axum::body::to_bytes(body, api::MAX_COMMAND_BYTES).await else {
        return api::refusal(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!(
                "the command body is over {} bytes (or was cut off)",
                api::MAX_COMMAND_BYTES
            ),
        );
    };
    api::command(State(shared), bytes).await
}

#[cfg(test)]
mod tests {
    use super::trusted_host;

    #[test]
    fn commands_are_trusted_from_ip_addresses_and_localhost_only() {
        for host in [
            "127.0.0.1:8080",
            "192.168.1.10:8080",
            "[::1]:8080",
            "localhost:8080",
            "LOCALHOST",
            "10.0.0.2",
        ] {
            assert!(trusted_host(host), "{host}");
        }
        for host in [
            "evil.example:8080",
            "evil.example",
            "",
            "127.0.0.1.nip.io:8080",
        ] {
            assert!(!trusted_host(host), "{host}");
        }
    }
}
