//! The cell's HTTP front end: a live dashboard for the operator and a JSON API for scripts and
//! line controllers that speak HTTP rather than Modbus (`chladni serve --http ADDR:PORT`).
//!
//! Routes (documented in docs/cell.md):
//! - `GET /`: the dashboard, one self-contained page (`dashboard.html`: no scripts or fonts from
//!   elsewhere, since a cell has no internet), fed by the two routes below it;
//! - `GET /api/status`: the [`CellStatus`] JSON; `GET /api/events`: the same as server-sent
//!   events, one per new status, at most one per [`MIN_EVENT_GAP`];
//! - `GET /api/plans`: the stored plans ([`PlansJson`], as `chladni device plans --json`);
//! - `POST /api/run` `{"slot": N, "repeat": M}` (`repeat` optional), `POST /api/stop`,
//!   `POST /api/clear-fault`;
//! - `POST /api/verify` (a photo), `GET /api/verify`, `GET /api/verify/photo.png`: the check
//!   of a run from a photo ([`verify`], its own body limit); `/api/events` also carries its
//!   results (`event: verify`).
//!
//! Every error is `{"error": "..."}` naming the value and the fix, with the status telling its
//! kind: 400 a request that is not what the route takes, 422 a slot that does not exist or
//! holds no plan, 409 the controller refused, 503 the link is down, 502 the controller answered
//! nonsense, 404/405 no such route. The handlers parse request bodies themselves (not axum's
//! `Json` extractor) so that these messages are ours and not a framework's.
//!
//! Like every front end, this one never talks to the link: it only calls [`Cell`].
//!
//! In front of the routes: [`super::guard`] (Host, Origin, JSON bodies, the token),
//! `tower-http`'s body limit ([`MAX_BODY`]), body-read timeout and request timeout
//! ([`REQUEST_TIMEOUT`], 504), and [`json_errors`], which turns any answer of the stack that
//! is not JSON (413, 408) into `{"error": ...}`. Connections ([`serve`]) are hyper's HTTP/1 with
//! its header-read timeout, which also closes idle keep-alive connections, and a cap per
//! [`super::net::Caps`].

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderValue, Method, StatusCode, Uri, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use chladni_media::shapes::failure::FailureJson;
use chladni_shared::icd::store::PLAN_SLOTS;
use futures_util::stream::{self, Stream};
use serde_json::Value;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, watch};
use tower_http::limit::RequestBodyLimitLayer;
use tower_http::timeout::{RequestBodyTimeoutLayer, TimeoutLayer};

use super::error::{ApiError, json_response, kind_of_status};
use super::guard::{self, Access};
use super::net::{self, Caps};
use super::ratelog;
use super::verify::{self, Verifier};
use super::{Cell, CellStatus};
use chladni_device::json::{PlanJson, PlansJson, RunNumberJson};

/// The shortest gap between two status events of one `/api/events` stream: the owner polls
/// every 100 ms, and a browser needs no more to draw a live plot.
pub const MIN_EVENT_GAP: Duration = Duration::from_millis(100);

/// The dashboard page, embedded so that the binary is the whole installation.
const DASHBOARD: &str = include_str!("dashboard.html");

/// The routes, for the message of a request that matches none.
const ROUTES: &str = "GET /, GET /api/status, GET /api/events, GET /api/plans, \
                      POST /api/run, POST /api/stop, POST /api/clear-fault, \
                      POST /api/verify, GET /api/verify, GET /api/verify/photo.png";

/// The largest request body taken (a run request is a few dozen bytes).
pub const MAX_BODY: usize = 4 * 1024;
/// How long a request may take from its head to its answer (a run waits for the link).
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(15);
/// How long a body may take to arrive.
pub(crate) const BODY_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a connection may take to send a request's head, and stay idle between requests.
pub(crate) const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// The same for connections beyond the cap (served one request, no keep-alive).
pub(crate) const OVERFLOW_HEADER_TIMEOUT: Duration = Duration::from_secs(2);
/// hyper's read buffer: headers beyond it get hyper's own bare 431 (the guard answers JSON
/// for anything above [`guard::MAX_HEADER_BYTES`] and below this).
const READ_BUFFER: usize = 64 * 1024;

/// How the HTTP front end is served.
#[derive(Debug, Clone)]
pub struct Options {
    /// Who may use it.
    pub access: Access,
    /// Connections served normally, and beyond that with a short header timeout.
    pub connections: usize,
    /// See [`Caps::http_overflow`].
    pub overflow: usize,
    /// What `POST /api/verify` checks photos by (and publishes to).
    pub verifier: Verifier,
}

impl Options {
    /// Loopback use without a token, with the caps of this process's open-file limit.
    pub fn local() -> Self {
        let caps = Caps::from_limit(net::open_file_limit(), 1);
        Options {
            access: Access::default(),
            connections: caps.http,
            overflow: caps.http_overflow,
            verifier: Verifier::new(None),
        }
    }
}

/// Serves the dashboard and the API on `listener`; it never returns on its own (accept errors
/// are logged and retried).
pub async fn serve(cell: Cell, listener: TcpListener, options: Options) -> std::io::Result<()> {
    let app = router_with(cell, options.access, options.verifier);
    let normal = Arc::new(Semaphore::new(options.connections));
    let overflow = Arc::new(Semaphore::new(options.overflow));
    loop {
        let (stream, peer) = net::accept(&listener, "http").await;
        let (permit, timeout, keep_alive) = match Arc::clone(&normal).try_acquire_owned() {
            Ok(permit) => (permit, HEADER_TIMEOUT, true),
            Err(_) => match Arc::clone(&overflow).try_acquire_owned() {
                Ok(permit) => (permit, OVERFLOW_HEADER_TIMEOUT, false),
                Err(_) => {
                    refuse_connection(&stream, peer);
                    continue;
                }
            },
        };
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        tokio::spawn(async move {
            let mut http1 = hyper::server::conn::http1::Builder::new();
            http1
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(timeout)
                .keep_alive(keep_alive)
                .max_buf_size(READ_BUFFER);
            let io = hyper_util::rt::TokioIo::new(stream);
            // A connection that fails or times out is the client's affair: it is closed.
            let _ = http1.serve_connection(io, service).with_upgrades().await;
            drop(permit);
        });
    }
}

/// A connection beyond every cap: a JSON 503 if the socket takes it at once, then closed.
fn refuse_connection(stream: &TcpStream, peer: std::net::SocketAddr) {
    let body = r#"{"error":"too_many_connections","message":"the server holds as many connections as it takes: try again in a few seconds"}"#;
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\nRetry-After: 2\r\n\r\n{body}",
        body.len()
    );
    let _ = stream.try_write(answer.as_bytes());
    ratelog::global().log(
        &peer.ip().to_string(),
        "http-cap",
        &format!("http {peer}: refused, the connection cap is reached"),
    );
}

/// The routes, on `cell`, behind the guard and the limits; public so that tests and other
/// servers can mount them.
pub fn router(cell: Cell, access: Access) -> Router {
    router_with(cell, access, Verifier::new(None))
}

/// The same with the photo check's routes on `verifier` ([`super::verify`]): a photo is far
/// larger than [`MAX_BODY`], so that route has its own limit inside the guard.
pub(crate) fn router_with(cell: Cell, access: Access, verifier: Verifier) -> Router {
    routes(cell)
        .layer(axum::Extension(verifier.clone()))
        .layer(RequestBodyLimitLayer::new(MAX_BODY))
        .merge(verify::routes(verifier))
        .layer(axum::middleware::from_fn_with_state(Arc::new(access), guard::check))
        .layer(RequestBodyTimeoutLayer::new(BODY_TIMEOUT))
        .layer(TimeoutLayer::with_status_code(StatusCode::GATEWAY_TIMEOUT, REQUEST_TIMEOUT))
        .layer(axum::middleware::map_response(json_errors))
}

/// Any error answer that is not JSON yet (the stack's own: 413, 504, a body that timed out)
/// becomes `{"error": ...}` with a message naming the limit.
pub async fn json_errors(response: Response) -> Response {
    let status = response.status();
    let is_json = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|t| t.as_bytes().starts_with(b"application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return response;
    }
    let text = axum::body::to_bytes(response.into_body(), MAX_BODY).await.unwrap_or_default();
    let text = String::from_utf8_lossy(&text);
    let message = match status {
        StatusCode::PAYLOAD_TOO_LARGE => {
            format!("the body is larger than {MAX_BODY} bytes: the API takes small JSON objects")
        }
        StatusCode::GATEWAY_TIMEOUT => format!(
            "no answer within {REQUEST_TIMEOUT:?} (the controller is slow or many requests \
             wait): try again"
        ),
        _ if text.trim().is_empty() => status.canonical_reason().unwrap_or("error").to_owned(),
        _ => format!("{}: {}", status.canonical_reason().unwrap_or("error"), text.trim()),
    };
    ApiError::new(status, kind_of_status(status), message).into_response()
}

/// The routes themselves.
fn routes(cell: Cell) -> Router {
    Router::new()
        .route("/", get(dashboard))
        .route("/api/status", get(status))
        .route("/api/events", get(events))
        .route("/api/plans", get(plans))
        .route("/api/run", post(run))
        .route("/api/stop", post(stop))
        .route("/api/clear-fault", post(clear_fault))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(cell)
}

async fn dashboard() -> Response {
    let mut response = Html(DASHBOARD).into_response();
    response.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    response
}

async fn status(State(cell): State<Cell>) -> Response {
    json_response(StatusCode::OK, &cell.status())
}

async fn plans(State(cell): State<Cell>) -> Result<Response, ApiError> {
    let (plans, free_bytes) = cell.plans()?;
    let plans = PlansJson { free_bytes, plans: plans.iter().map(PlanJson::from).collect() };
    Ok(json_response(StatusCode::OK, &plans))
}

async fn run(State(cell): State<Cell>, body: Bytes) -> Result<Response, ApiError> {
    let request = RunRequest::parse(&body)?;
    let started = cell.run(request.slot, request.repeat).await?;
    Ok(json_response(StatusCode::OK, &started))
}

async fn stop(State(cell): State<Cell>, body: Bytes) -> Result<Response, ApiError> {
    empty_object(&body)?;
    Ok(json_response(StatusCode::OK, &RunNumberJson { run: cell.stop().await? }))
}

async fn clear_fault(State(cell): State<Cell>, body: Bytes) -> Result<Response, ApiError> {
    empty_object(&body)?;
    Ok(json_response(StatusCode::OK, &RunNumberJson { run: cell.clear_fault().await? }))
}

/// Stop and clear-fault take no arguments: an empty body or `{}`.
fn empty_object(body: &[u8]) -> Result<(), ApiError> {
    let text = String::from_utf8_lossy(body);
    if text.trim().is_empty()
        || serde_json::from_slice::<Value>(body).is_ok_and(|v| v == serde_json::json!({}))
    {
        return Ok(());
    }
    Err(ApiError::bad_request(format!("the body is {text}: this command takes {{}} or nothing")))
}

async fn not_found(method: Method, uri: Uri) -> ApiError {
    let message = format!("no route {method} {}: the routes are {ROUTES}", uri.path());
    ApiError::new(StatusCode::NOT_FOUND, "not_found", message)
}

async fn method_not_allowed(method: Method, uri: Uri) -> ApiError {
    let message = format!("{} does not take {method}: the routes are {ROUTES}", uri.path());
    ApiError::new(StatusCode::METHOD_NOT_ALLOWED, "method_not_allowed", message)
}

/// The body of `POST /api/run`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RunRequest {
    /// The slot, as sent: [`Cell::run`] checks it against the store and names it.
    pub slot: u32,
    /// Repeat count instead of the plan's own (`None`: as stored).
    pub repeat: Option<u16>,
}

const RUN_BODY: &str =
    r#"send {"slot": N} or {"slot": N, "repeat": M} (GET /api/plans lists the slots)"#;

impl RunRequest {
    /// Reads `{"slot": N, "repeat": M}`; every error names what was wrong and the fix.
    pub fn parse(body: &[u8]) -> Result<Self, ApiError> {
        let value: Value = serde_json::from_slice(body).map_err(|e| {
            ApiError::bad_request(format!("the body is not JSON ({e}): {RUN_BODY}"))
        })?;
        let Value::Object(fields) = value else {
            return Err(ApiError::bad_request(format!(
                "the body is {value}, not a JSON object: {RUN_BODY}"
            )));
        };
        if let Some(key) = fields.keys().find(|k| !matches!(k.as_str(), "slot" | "repeat")) {
            return Err(ApiError::bad_request(format!("unknown key \"{key}\": {RUN_BODY}")));
        }
        let slot = match fields.get("slot") {
            None | Some(Value::Null) => {
                return Err(ApiError::bad_request(format!("\"slot\" is missing: {RUN_BODY}")));
            }
            Some(v) => slot_of(v)?,
        };
        let repeat = match fields.get("repeat") {
            None | Some(Value::Null) => None,
            Some(v) => Some(repeat_of(v)?),
        };
        Ok(RunRequest { slot, repeat })
    }
}

/// A slot number: a whole number; its range is the store's to check, but one past `u32` gets
/// the store's message here.
fn slot_of(v: &Value) -> Result<u32, ApiError> {
    let n = v.as_u64().ok_or_else(|| {
        ApiError::bad_request(format!(
            "slot {v} is not a slot number: slots are whole numbers 0..{}",
            PLAN_SLOTS - 1
        ))
    })?;
    u32::try_from(n).map_err(|_| {
        let message = format!("slot {n} does not exist: slots are 0..{}", PLAN_SLOTS - 1);
        ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "bad_slot", message)
    })
}

fn repeat_of(v: &Value) -> Result<u16, ApiError> {
    v.as_u64().and_then(|n| u16::try_from(n).ok()).ok_or_else(|| {
        ApiError::bad_request(format!(
            "repeat {v} is not a repeat count: a whole number 0..{}, or leave it out for the \
             plan's own",
            u16::MAX
        ))
    })
}

async fn events(
    State(cell): State<Cell>,
    axum::Extension(verifier): axum::Extension<Verifier>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let verified = verify::events(verifier.watch());
    Sse::new(stream::select(status_events(cell.watch()), verified)).keep_alive(KeepAlive::default())
}

/// The status stream: the current status at once, then each new one, no two closer than
/// [`MIN_EVENT_GAP`] (statuses published meanwhile are skipped: the latest one is sent). It
/// ends when the link owner does.
fn status_events(
    status: watch::Receiver<CellStatus>,
) -> impl Stream<Item = Result<Event, Infallible>> {
    stream::unfold((status, true), |(mut status, first)| async move {
        if !first {
            tokio::time::sleep(MIN_EVENT_GAP).await;
            status.changed().await.ok()?;
        }
        let event = status_event(&status.borrow_and_update());
        Some((Ok(event), (status, false)))
    })
}

fn status_event(status: &CellStatus) -> Event {
    let data = serde_json::to_string(status).unwrap_or_else(|e| {
        serde_json::json!(FailureJson::new("internal", &e.to_string())).to_string()
    });
    Event::default().event("status").data(data)
}

#[cfg(test)]
mod tests;
