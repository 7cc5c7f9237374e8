//! `ips start|stop|get|list|remove|reset|save|load|status`: one request to a running `ips serve`.
//! `ips align-cloud --service` and `ips diagnose --service` send theirs through [`request_data`].

use serde_json::Value;

use crate::BadInput;
use crate::cli::ServiceArgs;

/// How long a client waits for a reply. The service answers in turn, so this covers a queue of
/// slow requests (an align-cloud takes a fraction of a second, see serve.rs).
const REPLY_TIMEOUT_MS: i32 = 30_000;

/// Sends one request and returns the reply for printing (text or `--json`); a refused request
/// is bad input (exit 2) with the service's reason.
pub fn call(command: &str, ids: Vec<String>, args: &ServiceArgs) -> Result<String, BadInput> {
    call_with_path(command, ids, None, args)
}

/// `get`, optionally at a controller time (s).
pub fn get(time_s: Option<f64>, args: &ServiceArgs) -> Result<String, BadInput> {
    if time_s.is_some_and(|t| !t.is_finite()) {
        return Err(BadInput(
            "--at must be a finite controller time in s".to_owned(),
        ));
    }
    let mut request = protocol::service_request("get");
    request.body.time_s = time_s;
    let data = request_data(&args.service, &request)?;
    Ok(if args.json {
        format!("{}\n", serde_json::to_string(&data).unwrap_or_default())
    } else {
        text_of("get", &data)
    })
}

/// As [`call`], with a session file path (save, load).
pub fn call_with_path(
    command: &str,
    ids: Vec<String>,
    path: Option<String>,
    args: &ServiceArgs,
) -> Result<String, BadInput> {
    let mut request = protocol::service_request(command);
    request.body.ids = ids;
    request.body.path = path;
    let data = request_data(&args.service, &request)?;
    Ok(if args.json {
        format!("{}\n", serde_json::to_string(&data).unwrap_or_default())
    } else {
        text_of(command, &data)
    })
}

/// The service's align reply for people: the pose, the residual and how the search went.
pub fn align_text(data: &Value) -> String {
    let numbers = |key: &str| -> Vec<String> {
        (0..3)
            .map(|i| format!("{:.6}", data["pose"][key][i].as_f64().unwrap_or(f64::NAN)))
            .collect()
    };
    let mut text = format!(
        "base_from_part: xyz [m] {}, rpy [rad] {}\nresidual rms {:.4} mm, max {:.4} mm, {} iterations in {:.1} ms\n",
        numbers("xyz").join(" "),
        numbers("rpy").join(" "),
        data["rms"].as_f64().unwrap_or(f64::NAN) * 1e3,
        data["max"].as_f64().unwrap_or(f64::NAN) * 1e3,
        data["iterations"],
        data["time_s"].as_f64().unwrap_or(f64::NAN) * 1e3,
    );
    if data["ambiguous"] == true {
        text += "AMBIGUOUS: other poses fit these touches as well (see --json candidates)\n";
    }
    text
}

/// Sends one request to the service at `endpoint` and returns the reply's data; a refused
/// request is bad input (exit 2) with the service's reason.
pub fn request_data(endpoint: &str, request: &protocol::ServiceRequest) -> Result<Value, BadInput> {
    let context = zmq::Context::new();
    let socket = context.socket(zmq::REQ).map_err(BadInput::new)?;
    socket.set_linger(0).map_err(BadInput::new)?;
    socket
        .set_rcvtimeo(REPLY_TIMEOUT_MS)
        .map_err(BadInput::new)?;
    socket.set_sndtimeo(5_000).map_err(BadInput::new)?;
    socket
        .connect(endpoint)
        .map_err(|error| BadInput(format!("{endpoint}: {error}")))?;
    let text = protocol::to_json(request).map_err(BadInput::new)?;
    socket.send(text.as_bytes(), 0).map_err(BadInput::new)?;
    let reply = socket.recv_bytes(0).map_err(|_| {
        BadInput(format!(
            "no reply from the service at {endpoint} within {} s",
            REPLY_TIMEOUT_MS / 1000
        ))
    })?;
    let reply: protocol::ServiceReply = serde_json::from_slice(&reply)
        .map_err(|error| BadInput(format!("bad reply from the service: {error}")))?;
    if reply.body.ok {
        Ok(reply.body.data)
    } else {
        Err(BadInput(
            reply.body.reason.unwrap_or_else(|| "refused".to_owned()),
        ))
    }
}

fn text_of(command: &str, data: &Value) -> String {
    match command {
        "get" => format!("inspection {} at q = {}\n", data["id"], data["q"]),
        "list" => {
            let mut text = String::new();
            for inspection in data["inspections"].as_array().into_iter().flatten() {
                text += &format!(
                    "{:>6}  q = {}\n",
                    inspection["id"].as_str().unwrap_or("?"),
                    inspection["q"]
                );
            }
            if text.is_empty() {
                text = "no inspections\n".to_owned();
            }
            text
        }
        _ => format!("{data}\n"),
    }
}
