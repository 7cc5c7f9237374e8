//! `ips serve`: the alignment service (the `align-service` library) until SIGINT or SIGTERM.

use align_service::server::{self, ServiceError};
use clap::Args;
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;
use std::path::PathBuf;
use tracing_subscriber::EnvFilter;

use crate::CliError;

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Session file naming robot, tool and part (its inspections start the list when no
    /// journal exists yet).
    #[arg(long, value_name = "FILE")]
    pub session: PathBuf,
    /// Journal of inspections (appended and flushed before every acknowledgement).
    #[arg(long, value_name = "FILE", default_value = "inspections.journal")]
    pub journal: PathBuf,
    #[arg(long, default_value = "tcp://*:4000")]
    pub rep: String,
    #[arg(long, default_value = "tcp://127.0.0.1:2000")]
    pub bridge_rep: String,
    #[arg(long, default_value = "tcp://127.0.0.1:3000")]
    pub bridge_pub: String,
    /// Oldest joint state a `get` accepts, s.
    #[arg(long, default_value_t = 0.1)]
    pub max_sample_age: f64,
    /// Fastest tool a `get` accepts, m/s.
    #[arg(long, default_value_t = 0.005)]
    pub max_tool_speed: f64,
    /// A directory whose regular files `load`, `save` and `align-cloud` requests may name;
    /// repeatable. Without it, only the session file's folder.
    #[arg(long = "data-dir", value_name = "DIR")]
    pub data_dirs: Vec<PathBuf>,
    /// What a new journal starts with when the session file holds inspections: keep them, or
    /// drop them and start empty. An existing journal continues its own list either way (the
    /// start-up log says which list is in use).
    #[arg(long, value_enum, value_name = "WHAT", default_value_t = SessionInspections::Keep)]
    pub session_inspections: SessionInspections,
    /// The digital input a touch-trigger probe is wired to (DI0-DI7 standard, CI0-CI7
    /// configurable, TI0-TI1 tool inputs, as the hwState's `digital_inputs` bits 0-17). While
    /// mirroring, each rising edge captures an inspection without a `get`, at the edge's
    /// controller time: the midpoint of the samples around it, joints interpolated there
    /// (worst case half a sample period off). Without it, only `get` captures.
    #[arg(long, value_name = "INPUT")]
    pub trigger: Option<protocol::DigitalInput>,
    /// Also serve the operator's page at http://ADDR/: HOST:PORT, or a bare PORT on this
    /// machine only (127.0.0.1); `--http` alone is 127.0.0.1:8080, `--http 0` picks a free
    /// port. The page is a client of the REP socket and is neither authenticated nor encrypted:
    /// bind it to loopback or the cell's network only. The READY line then adds
    /// `http=http://HOST:PORT`.
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        default_missing_value = "127.0.0.1:8080",
        value_parser = parse_http_listen
    )]
    pub http: Option<String>,
}

/// `--session-inspections`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SessionInspections {
    Keep,
    Drop,
}

impl ServeArgs {
    pub fn config(&self) -> server::Config {
        server::Config {
            session: self.session.clone(),
            journal: self.journal.clone(),
            rep: self.rep.clone(),
            bridge_rep: self.bridge_rep.clone(),
            bridge_pub: self.bridge_pub.clone(),
            max_sample_age_s: self.max_sample_age,
            max_tool_speed_m_s: self.max_tool_speed,
            data_dirs: self.data_dirs.clone(),
            keep_session_inspections: self.session_inspections == SessionInspections::Keep,
            trigger: self.trigger,
        }
    }
}

/// `--http`'s address: a bare port means loopback, never every interface.
fn parse_http_listen(text: &str) -> Result<String, String> {
    if !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit()) {
        let port: u16 = text
            .parse()
            .map_err(|_| format!("'{text}' is not a port (expected 0-65535)"))?;
        return Ok(format!("127.0.0.1:{port}"));
    }
    Ok(text.to_owned())
}

/// Serves until a signal; prints `READY rep=ENDPOINT` (and ` http=URL` with `--http`) on stdout
/// once requests are answered.
pub fn run(args: &ServeArgs) -> Result<String, CliError> {
    init_logs();
    let mut signals = Signals::new([SIGINT, SIGTERM])
        .map_err(|error| CliError::Failure(format!("cannot handle signals: {error}")))?;
    let config = args.config();
    let service = server::start(&config).map_err(|error| match error {
        ServiceError::BadInput(bad) => CliError::BadInput(bad),
        other => CliError::Failure(other.to_string()),
    })?;
    for warning in service.journal_report.warnings() {
        tracing::warn!("{warning}");
    }
    tracing::info!("{}", service.inspections_note);
    let page = match &args.http {
        Some(listen) => match start_page(listen, &config, &service.rep_endpoint) {
            Ok(page) => Some(page),
            Err(error) => {
                service.stop();
                return Err(error);
            }
        },
        None => None,
    };
    match &page {
        Some(page) => {
            tracing::info!("operator page at {}/", page.url());
            println!("READY rep={} http={}", service.rep_endpoint, page.url());
        }
        None => println!("READY rep={}", service.rep_endpoint),
    }
    signals.forever().next();
    if let Some(page) = page {
        page.stop();
    }
    service.stop();
    Ok(String::new())
}

/// The operator's page against the service's bound REP endpoint, in this process.
fn start_page(
    listen: &str,
    config: &server::Config,
    rep_endpoint: &str,
) -> Result<operator_page::Handle, CliError> {
    operator_page::start(&operator_page::Config {
        listen: listen.to_owned(),
        service: rep_endpoint.to_owned(),
        bridge_rep: config.bridge_rep.clone(),
        bridge_pub: config.bridge_pub.clone(),
        session: config.session.clone(),
        reply_timeout: crate::client::DEFAULT_REPLY_TIMEOUT,
    })
    .map_err(|error| match error {
        operator_page::PageError::Bind { .. } | operator_page::PageError::Session(_) => {
            CliError::BadInput(align_service::BadInput(error.to_string()))
        }
        other => CliError::Failure(other.to_string()),
    })
}

/// Logs to stderr at the levels `RUST_LOG` names (default `info`; `RUST_LOG=debug` adds one
/// line per request); stdout carries only the READY line.
fn init_logs() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt().with_env_filter(filter);
    let _ = logs
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}
