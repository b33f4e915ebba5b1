//! The rig as a snapshot camera: a thread that follows the controller (its status polled every
//! [`POLL`] as any second client does, the parts moved for what was driven between polls) and
//! an HTTP server (axum on tokio) that answers each frame with the state of a poll made after
//! the request arrived.
//!
//! Routes: GET `/frame.png`, `/frame.jpg` (a photo; header `X-Frame-Time`: the wall time of
//! the state shown, unix seconds), `/truth` ([`Truth`] with `time`); POST `/pick` (the robot:
//! after the pick time, the part at the pose given leaves the plate, [`PickRequest`]). At most
//! [`MAX_REQUESTS`] frames and truths are answered at once (more: 503), one pick at a time. With [`Fail`], frame requests
//! after the first N fail on purpose, for tests of cameras that break.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::{HeaderName, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use chladni_device::client::{DeviceClient, DeviceError};
use chladni_media::vision::synth::Placed;
use chladni_shared::icd::link::StatusReport;
use serde::{Deserialize, Serialize};
use tokio::sync::{Semaphore, mpsc, oneshot, watch};

use crate::RigError;
use crate::camera::{Camera, Format};
use crate::rig::{PartTruth, Rig, Truth};

/// How often the controller's status is polled.
pub const POLL: Duration = Duration::from_millis(20);
/// How long a request waits for a fresh poll before it is answered 503.
pub const FRESH_LIMIT: Duration = Duration::from_secs(5);
/// Requests answered at once.
pub const MAX_REQUESTS: usize = 4;
/// The rig's session name on the controller's link.
pub const CLIENT_NAME: &str = "rig";
/// The header carrying the wall time of the state a frame shows.
pub const FRAME_TIME: &str = "x-frame-time";
/// The largest `/pick` body (bytes): a pick is three numbers.
pub const PICK_BODY_LIMIT: usize = 1024;
/// The robot's default pick time: from the request to the part gone.
pub const DEFAULT_PICK_TIME: Duration = Duration::from_secs(2);
/// The longest pick time `--pick-time-s` takes (s).
pub const MAX_PICK_TIME_S: f64 = 600.0;

/// How a failing camera fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailMode {
    /// The request is accepted and never answered.
    Hang,
    /// 200 with bytes that are no image.
    Garbage,
    /// The last frame's bytes again, every time (a frozen sensor).
    Frozen,
    /// 500 Internal Server Error.
    Status500,
}

/// Failure injection: frame requests after the first `after_frames` fail by `mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fail {
    /// Frames answered normally first.
    pub after_frames: u64,
    /// How the later ones fail.
    pub mode: FailMode,
}

/// How the rig is served.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The controller's link: a serial device or `tcp://HOST:PORT`.
    pub port: String,
    /// Where to listen.
    pub listen: SocketAddr,
    /// Failure injection.
    pub fail: Option<Fail>,
    /// Seed of the frames' sensor noise (each frame its own).
    pub seed: u64,
    /// How long a pick takes: the part leaves the plate this long after `POST /pick`.
    pub pick_time: Duration,
}

/// `POST /pick`'s body: the robot picks the part whose centroid lies nearest (`x_mm`,
/// `y_mm`) within `radius_mm`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PickRequest {
    /// Where the gripper closes (mm, plate frame).
    pub x_mm: f64,
    /// Where the gripper closes (mm).
    pub y_mm: f64,
    /// How far from it a centroid may lie (mm, > 0).
    pub radius_mm: f64,
}

impl PickRequest {
    /// The request parsed from JSON and checked: finite numbers, a radius > 0. Errors are
    /// `(name, message)`.
    pub fn parse(body: &[u8]) -> Result<PickRequest, (&'static str, String)> {
        let r: PickRequest = serde_json::from_slice(body).map_err(|e| {
            (
                "bad_json",
                format!("the pick is not {{\"x_mm\": X, \"y_mm\": Y, \"radius_mm\": R}}: {e}"),
            )
        })?;
        let fields = [("x_mm", r.x_mm), ("y_mm", r.y_mm), ("radius_mm", r.radius_mm)];
        if let Some((name, v)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Err(("bad_value", format!("{name} = {v}: give a finite number (mm)")));
        }
        if r.radius_mm <= 0.0 {
            let m =
                format!("radius_mm = {}: give a radius > 0 mm (the gripper's reach)", r.radius_mm);
            return Err(("bad_value", m));
        }
        Ok(r)
    }
}

/// A pick waiting for its time, and where its answer goes.
struct PickJob {
    due: Instant,
    request: PickRequest,
    reply: oneshot::Sender<Option<PartTruth>>,
}

/// `/pick`'s answer when a part was picked.
#[derive(Debug, Serialize)]
struct Picked<'a> {
    picked: &'a PartTruth,
    pick_time_s: f64,
}

/// The state after one poll.
#[derive(Debug)]
struct Snapshot {
    /// When the poll was sent.
    started: Instant,
    /// When its answer arrived (the time of the state).
    time: SystemTime,
    placed: Vec<Placed>,
    truth: Truth,
}

impl Snapshot {
    fn of(rig: &Rig, started: Instant) -> Snapshot {
        Snapshot { started, time: SystemTime::now(), placed: rig.placed(), truth: rig.truth() }
    }

    /// The time of the state, unix seconds.
    fn unix_s(&self) -> f64 {
        self.time.duration_since(SystemTime::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
    }
}

/// `/truth`'s answer: the state and its wall time.
#[derive(Debug, Serialize)]
struct TruthAt<'a> {
    #[serde(flatten)]
    truth: &'a Truth,
    /// Unix seconds.
    time: f64,
}

/// What the handlers share.
struct App {
    camera: Camera,
    snapshots: watch::Receiver<Arc<Snapshot>>,
    frames: AtomicU64,
    fail: Option<Fail>,
    last: Mutex<Option<(Vec<u8>, Format)>>,
    slots: Semaphore,
    seed: u64,
    picks: std::sync::mpsc::Sender<PickJob>,
    picking: AtomicBool,
    pick_time: Duration,
}

/// Follows the controller at `options.port` and serves the rig's camera on `options.listen`
/// until `stop` receives (Ok) or the link is lost ([`RigError::LinkLost`]). `announce` is
/// called with the address bound, once the controller has answered.
pub fn serve(
    rig: Rig,
    options: &ServeOptions,
    announce: impl FnOnce(SocketAddr) -> std::io::Result<()>,
    stop: mpsc::UnboundedReceiver<()>,
) -> Result<(), RigError> {
    let port = options.port.clone();
    let link = |reason| RigError::Link { port: port.clone(), reason };
    let mut client = DeviceClient::open(&options.port, CLIENT_NAME).map_err(link)?;
    let started = Instant::now();
    let first = client.status().map_err(link)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(RigError::Runtime)?;
    let (tx, rx) = watch::channel(Arc::new(Snapshot::of(&rig, started)));
    let (picks, pick_rx) = std::sync::mpsc::channel();
    let app = App {
        camera: rig.camera(),
        snapshots: rx,
        frames: AtomicU64::new(0),
        fail: options.fail,
        last: Mutex::new(None),
        slots: Semaphore::new(MAX_REQUESTS),
        seed: options.seed,
        picks,
        picking: AtomicBool::new(false),
        pick_time: options.pick_time,
    };
    let halt = Arc::new(AtomicBool::new(false));
    let (ended_tx, ended_rx) = oneshot::channel();
    let follower = {
        let halt = halt.clone();
        std::thread::spawn(move || {
            let _ = ended_tx.send(follow(client, rig, first, (&tx, &pick_rx), &halt));
        })
    };
    let result = runtime.block_on(run(app, options.listen, announce, stop, ended_rx));
    halt.store(true, Ordering::Relaxed);
    let _ = follower.join();
    // Open connections (a hanging frame's among them) are dropped with the runtime.
    runtime.shutdown_timeout(Duration::from_secs(1));
    result.map_err(|e| match e {
        Ended::Lost(reason) => RigError::LinkLost { port: options.port.clone(), reason },
        Ended::Other(e) => e,
    })
}

/// Why the server ended with an error.
enum Ended {
    Lost(DeviceError),
    Other(RigError),
}

/// Binds, announces, and serves until stopped or the follower ends.
async fn run(
    app: App,
    listen: SocketAddr,
    announce: impl FnOnce(SocketAddr) -> std::io::Result<()>,
    mut stop: mpsc::UnboundedReceiver<()>,
    ended: oneshot::Receiver<Result<(), DeviceError>>,
) -> Result<(), Ended> {
    let listener = tokio::net::TcpListener::bind(listen)
        .await
        .map_err(|reason| Ended::Other(RigError::Listen { addr: listen, reason }))?;
    let addr = listener.local_addr().map_err(|e| Ended::Other(RigError::Runtime(e)))?;
    announce(addr).map_err(|e| Ended::Other(RigError::Runtime(e)))?;
    let router = Router::new()
        .route("/frame.png", get(png))
        .route("/frame.jpg", get(jpg))
        .route("/truth", get(truth))
        .route("/pick", post(pick).layer(DefaultBodyLimit::max(PICK_BODY_LIMIT)))
        .fallback(not_found)
        .with_state(Arc::new(app));
    tokio::select! {
        _ = stop.recv() => Ok(()),
        result = ended => match result {
            Ok(Err(e)) => Err(Ended::Lost(e)),
            // The follower only ends on its own when the link fails.
            _ => Err(Ended::Lost(DeviceError::Closed)),
        },
        served = async { axum::serve(listener, router).await } => {
            Err(Ended::Other(RigError::Runtime(served.err().unwrap_or_else(|| {
                std::io::Error::other("the HTTP server stopped")
            }))))
        }
    }
}

/// The follower: polls the status every [`POLL`], moves the parts for what was driven since
/// the last poll, removes the parts picked whose time has come, and publishes the state (then
/// answers those picks: a `/truth` asked after the answer shows the part gone); until `halt`
/// or a link error.
fn follow(
    mut client: DeviceClient,
    mut rig: Rig,
    mut before: StatusReport,
    (tx, picks): (&watch::Sender<Arc<Snapshot>>, &std::sync::mpsc::Receiver<PickJob>),
    halt: &AtomicBool,
) -> Result<(), DeviceError> {
    let mut waiting: Vec<PickJob> = Vec::new();
    while !halt.load(Ordering::Relaxed) {
        let started = Instant::now();
        let after = client.status()?;
        rig.step(&before, &after);
        waiting.extend(picks.try_iter());
        let (due, later): (Vec<PickJob>, Vec<PickJob>) =
            waiting.drain(..).partition(|j| j.due <= started);
        waiting = later;
        let done: Vec<_> = due
            .into_iter()
            .map(|j| (rig.pick(j.request.x_mm, j.request.y_mm, j.request.radius_mm), j.reply))
            .collect();
        tx.send_replace(Arc::new(Snapshot::of(&rig, started)));
        for (picked, reply) in done {
            let _ = reply.send(picked);
        }
        before = after;
        std::thread::sleep(POLL.saturating_sub(started.elapsed()));
    }
    Ok(())
}

/// The first state polled after `since`; 503 when the link is gone or no poll comes in
/// [`FRESH_LIMIT`].
async fn fresh(app: &App, since: Instant) -> Result<Arc<Snapshot>, Response> {
    let mut rx = app.snapshots.clone();
    let wait = async {
        loop {
            {
                let s = rx.borrow_and_update();
                if s.started >= since {
                    return Some(s.clone());
                }
            }
            if rx.changed().await.is_err() {
                return None;
            }
        }
    };
    match tokio::time::timeout(FRESH_LIMIT, wait).await {
        Ok(Some(s)) => Ok(s),
        Ok(None) => Err(text(StatusCode::SERVICE_UNAVAILABLE, "the controller link is lost\n")),
        Err(_) => Err(text(
            StatusCode::SERVICE_UNAVAILABLE,
            "the controller's status did not come within 5 s\n",
        )),
    }
}

/// A plain-text answer.
fn text(status: StatusCode, body: &'static str) -> Response {
    (status, [(header::CONTENT_TYPE, "text/plain; charset=utf-8")], body).into_response()
}

/// A frame's answer: the image, its type, the time of its state, never cached.
fn image(bytes: Vec<u8>, format: Format, unix_s: f64) -> Response {
    let time =
        HeaderValue::from_str(&format!("{unix_s:.6}")).unwrap_or(HeaderValue::from_static("0"));
    let headers = [
        (header::CONTENT_TYPE, HeaderValue::from_static(format.content_type())),
        (header::CACHE_CONTROL, HeaderValue::from_static("no-store")),
        (HeaderName::from_static(FRAME_TIME), time),
    ];
    (headers, bytes).into_response()
}

async fn png(State(app): State<Arc<App>>) -> Response {
    frame(app, Format::Png).await
}

async fn jpg(State(app): State<Arc<App>>) -> Response {
    frame(app, Format::Jpeg).await
}

/// The unix time now (s).
fn now_s() -> f64 {
    SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// A frame of the state polled after the request arrived, or the failure asked for.
async fn frame(app: Arc<App>, format: Format) -> Response {
    let since = Instant::now();
    let n = app.frames.fetch_add(1, Ordering::Relaxed);
    if let Some(fail) = app.fail.filter(|f| n >= f.after_frames) {
        match fail.mode {
            FailMode::Hang => return std::future::pending::<Response>().await,
            FailMode::Garbage => {
                let body = b"no image: the rig's camera fails on purpose (--fail-mode garbage)\n";
                return image(body.to_vec(), format, now_s());
            }
            FailMode::Status500 => {
                let body = "the rig's camera fails on purpose (--fail-mode status500)\n";
                return text(StatusCode::INTERNAL_SERVER_ERROR, body);
            }
            FailMode::Frozen => {
                let last = app.last.lock().ok().and_then(|l| l.clone());
                if let Some((bytes, format)) = last {
                    return image(bytes, format, now_s());
                }
            }
        }
    }
    let Ok(_slot) = app.slots.try_acquire() else {
        return text(StatusCode::SERVICE_UNAVAILABLE, "the camera is busy: try again\n");
    };
    let snapshot = match fresh(&app, since).await {
        Ok(s) => s,
        Err(answer) => return answer,
    };
    let seed = app.seed ^ n.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let job = {
        let app = app.clone();
        let placed = snapshot.placed.clone();
        tokio::task::spawn_blocking(move || app.camera.frame(placed, seed, format))
    };
    match job.await {
        Ok(Ok(bytes)) => {
            if let Ok(mut last) = app.last.lock() {
                *last = Some((bytes.clone(), format));
            }
            image(bytes, format, snapshot.unix_s())
        }
        _ => text(StatusCode::INTERNAL_SERVER_ERROR, "the frame could not be rendered\n"),
    }
}

/// The true state polled after the request arrived.
async fn truth(State(app): State<Arc<App>>) -> Response {
    let Ok(_slot) = app.slots.try_acquire() else {
        return text(StatusCode::SERVICE_UNAVAILABLE, "the camera is busy: try again\n");
    };
    let snapshot = match fresh(&app, Instant::now()).await {
        Ok(s) => s,
        Err(answer) => return answer,
    };
    let at = TruthAt { truth: &snapshot.truth, time: snapshot.unix_s() };
    match serde_json::to_vec(&at) {
        Ok(body) => ([(header::CONTENT_TYPE, "application/json")], body).into_response(),
        Err(_) => text(StatusCode::INTERNAL_SERVER_ERROR, "the state could not be written\n"),
    }
}

async fn not_found() -> Response {
    text(
        StatusCode::NOT_FOUND,
        "no such route: the rig serves GET /frame.png, /frame.jpg, /truth and POST /pick\n",
    )
}

/// A JSON failure `{"error": NAME, "message"}` with `status`.
fn failure(status: StatusCode, name: &str, message: String) -> Response {
    let body = serde_json::json!({ "error": name, "message": message });
    (status, [(header::CONTENT_TYPE, "application/json")], body.to_string()).into_response()
}

/// Clears the one-pick-at-a-time flag when the pick's answer is done (or dropped).
struct PickSlot<'a>(&'a AtomicBool);

impl Drop for PickSlot<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// `POST /pick`: after the pick time, the part nearest the pose within the radius leaves the
/// plate. 200 `{"picked": {part, x_mm, y_mm, theta_deg, lost}, "pick_time_s"}`; 404
/// `no_part` when none lies there; 400 `bad_json` / `bad_value`; 409 `busy` while another
/// pick is under way; 413 for a body over [`PICK_BODY_LIMIT`]; 503 when the link is lost.
async fn pick(State(app): State<Arc<App>>, body: Bytes) -> Response {
    let request = match PickRequest::parse(&body) {
        Ok(r) => r,
        Err((name, message)) => return failure(StatusCode::BAD_REQUEST, name, message),
    };
    if app.picking.swap(true, Ordering::AcqRel) {
        let m = "another pick is under way: ask again when it has answered".to_owned();
        return failure(StatusCode::CONFLICT, "busy", m);
    }
    let _slot = PickSlot(&app.picking);
    let (reply, answer) = oneshot::channel();
    let job = PickJob { due: Instant::now() + app.pick_time, request, reply };
    let lost = || text(StatusCode::SERVICE_UNAVAILABLE, "the controller link is lost\n");
    if app.picks.send(job).is_err() {
        return lost();
    }
    // The follower answers at its first poll after the pick time; none: the link is gone.
    let Ok(picked) = answer.await else { return lost() };
    let pick_time_s = app.pick_time.as_secs_f64();
    match picked {
        Some(p) => match serde_json::to_vec(&Picked { picked: &p, pick_time_s }) {
            Ok(body) => ([(header::CONTENT_TYPE, "application/json")], body).into_response(),
            Err(_) => text(StatusCode::INTERNAL_SERVER_ERROR, "the pick could not be written\n"),
        },
        None => failure(
            StatusCode::NOT_FOUND,
            "no_part",
            format!(
                "no part's centroid lies within {} mm of ({}, {}) mm: nothing was picked (GET \
                 /truth shows where the parts are)",
                request.radius_mm, request.x_mm, request.y_mm
            ),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pick_body_is_three_finite_numbers_and_a_positive_radius() {
        let ok = PickRequest::parse(br#"{"x_mm": 150, "y_mm": 100.5, "radius_mm": 4}"#);
        assert_eq!(ok, Ok(PickRequest { x_mm: 150.0, y_mm: 100.5, radius_mm: 4.0 }));
        for (body, name, says) in [
            (&br#"{"x_mm": 1, "y_mm": 2}"#[..], "bad_json", "missing field `radius_mm`"),
            (br#"{"x_mm": 1, "y_mm": 2, "radius_mm": 3, "theta": 0}"#, "bad_json", "`theta`"),
            (br#"{"x_mm": "1", "y_mm": 2, "radius_mm": 3}"#, "bad_json", "invalid type"),
            (br#"{"x_mm": 1, "y_mm": 2, "radius_mm": 0}"#, "bad_value", "radius_mm = 0"),
            (br#"{"x_mm": 1, "y_mm": 2, "radius_mm": 1e999}"#, "bad_json", "x_mm"),
            (b"", "bad_json", "EOF"),
        ] {
            let (n, message) = PickRequest::parse(body).unwrap_err();
            assert_eq!(n, name, "{message}");
            assert!(message.contains(says), "{message}");
        }
    }
}
