//! The HTTP server (axum on a single-threaded tokio runtime of its own thread): read only,
//! every asset embedded in the binary (a plant network has no internet), no credential in
//! anything it serves.
//!
//! | path | what |
//! |---|---|
//! | `/` | the status page (`assets/index.html`, its script and style) |
//! | `/api/status` | the page's document ([`crate::Status`], JSON) |
//! | `/metrics` | the Prometheus metrics (text format 0.0.4; OpenMetrics when the scraper's `Accept` asks for it) |
//! | `/healthz` | `ok` while the server runs |
//!
//! Anything else is 404; a method other than GET or HEAD on a known path 405; a request
//! whose header exceeds hyper's limit (about 400 KB) 431; the certifier never sees any of it.

use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use axum::Router;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

use crate::{ServeError, Shared};

const INDEX: &str = include_str!("../assets/index.html");
const SCRIPT: &str = include_str!("../assets/app.js");
const STYLE: &str = include_str!("../assets/style.css");

/// What a listener serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Routes {
    /// The page, its document, the metrics and the health check (`--serve`).
    All,
    /// The metrics and the health check only (`--metrics`).
    Metrics,
}

/// A running server; dropping it stops it.
pub struct Server {
    addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Bind `addr` and serve `routes` of `shared` from a thread of its own.
    pub(crate) fn start(
        shared: Arc<Shared>,
        addr: SocketAddr,
        routes: Routes,
    ) -> Result<Self, ServeError> {
        let listener =
            TcpListener::bind(addr).map_err(|source| ServeError::Bind { addr, source })?;
        let addr = listener.local_addr().map_err(|source| ServeError::Bind { addr, source })?;
        listener.set_nonblocking(true).map_err(|source| ServeError::Bind { addr, source })?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(ServeError::Runtime)?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let app = router(shared, routes);
        let thread = std::thread::Builder::new()
            .name(format!("streamcert-serve {addr}"))
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else { return };
                    let shutdown = async {
                        let _ = stopped.await;
                    };
                    let _ = axum::serve(listener, app).with_graceful_shutdown(shutdown).await;
                });
            })
            .map_err(ServeError::Runtime)?;
        Ok(Self { addr, stop: Some(stop), thread: Some(thread) })
    }

    /// The address it listens on (the port chosen when `:0` was asked for).
    #[must_use]
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn router(shared: Arc<Shared>, routes: Routes) -> Router {
    let r = Router::new().route("/metrics", get(metrics)).route("/healthz", get(|| async { "ok" }));
    let r = match routes {
        Routes::Metrics => r,
        Routes::All => r
            .route("/", get(|| async { asset(INDEX, "text/html; charset=utf-8") }))
            .route("/app.js", get(|| async { asset(SCRIPT, "text/javascript; charset=utf-8") }))
            .route("/style.css", get(|| async { asset(STYLE, "text/css; charset=utf-8") }))
            .route("/api/status", get(status)),
    };
    r.fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") }).with_state(shared)
}

/// An embedded asset, never cached (the page is the process's own).
fn asset(body: &'static str, kind: &'static str) -> Response {
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(kind));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static("default-src 'self'; img-src 'self' data:"),
    );
    r
}

/// The metrics in the format the scraper asks for: OpenMetrics when its `Accept` header names
/// it (as Prometheus' own scraper does), else the text format 0.0.4 (`curl`, `promtool`).
async fn metrics(State(shared): State<Arc<Shared>>, headers: axum::http::HeaderMap) -> Response {
    let open = shared.metrics_text(Instant::now());
    let openmetrics = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .any(|v| v.contains("application/openmetrics-text"));
    let (body, kind) = if openmetrics {
        (open, "application/openmetrics-text; version=1.0.0; charset=utf-8")
    } else {
        (crate::metrics::to_text_format(&open), "text/plain; version=0.0.4; charset=utf-8")
    };
    let mut r = body.into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(kind));
    r
}

async fn status(State(shared): State<Arc<Shared>>) -> Response {
    let doc = shared.status().at(Instant::now());
    let body = serde_json::to_string(&doc).unwrap_or_else(|_| "{}".into());
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}
