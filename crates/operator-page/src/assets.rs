//! The page itself, embedded in the binary: the page works with nothing but `ips serve`
//! reachable (DESIGN.md 6.6), so every script, style and library is served from here.

use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};

const INDEX_HTML: &str = include_str!("../assets/index.html");
const PAGE_JS: &str = include_str!("../assets/page.js");
const TWIN_JS: &str = include_str!("../assets/twin.js");
const PAGE_CSS: &str = include_str!("../assets/page.css");
/// three.js 0.170.0 (MIT), vendored by `scripts/vendor-web.sh`.
const THREE_JS: &str = include_str!("../assets/vendor/three.module.min.js");
const THREE_LICENSE: &str = include_str!("../assets/vendor/three.LICENSE");

const JAVASCRIPT: &str = "text/javascript; charset=utf-8";

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        StatusCode::OK,
        [
            (header::CONTENT_TYPE, content_type),
            // The page is tied to this binary: a browser must not keep an older one.
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

pub async fn index() -> Response {
    asset("text/html; charset=utf-8", INDEX_HTML)
}

pub async fn page_js() -> Response {
    asset(JAVASCRIPT, PAGE_JS)
}

pub async fn twin_js() -> Response {
    asset(JAVASCRIPT, TWIN_JS)
}

pub async fn page_css() -> Response {
    asset("text/css; charset=utf-8", PAGE_CSS)
}

pub async fn three_js() -> Response {
    asset(JAVASCRIPT, THREE_JS)
}

pub async fn three_license() -> Response {
    asset("text/plain; charset=utf-8", THREE_LICENSE)
}
