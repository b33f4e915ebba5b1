//! The cell checks a run from a photo (docs/cell.md, "Verifying a run from a photo"): whatever
//! takes the picture posts it to `POST /api/verify` (`image/png` or `image/jpeg`, at most
//! [`MAX_PHOTO_BYTES`], refused from `Content-Length` before it is read and from the image
//! header before it is decoded); the parts in it are located and judged against the plan
//! `chladni serve --verify-plan` was given ([`chladni_media::vision::verify`]), and the result is
//! answered and published: `event: verify` on `/api/events`, `GET /api/verify` (the last
//! one), `GET /api/verify/photo.png` (the rectified photo with the found outlines), and the
//! Modbus input registers of [`Verifier::registers`].
//!
//! One photo is examined at a time (a second waits its turn): the work is CPU-bound and runs
//! on tokio's blocking pool, never on the threads that serve the other routes. A photo that
//! cannot be examined (not a photo, no plate in it) is answered 422 and published too, with
//! result code [`ResultCode::Refused`], so that a PLC never reads an old "ok" after a failed
//! check.
//!
//! The content type is part of the guard ([`check_photo_type`]): like `application/json`,
//! `image/png` and `image/jpeg` are not among the types a form or a no-CORS fetch may send, so
//! a page from another site cannot post a photo without a CORS preflight, which this server
//! never grants; the Origin, Host and token rules are those of every other POST.

use std::convert::Infallible;
use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::sse::Event;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use futures_util::stream::{self, Stream};
use serde_json::{Value, json};
use tokio::sync::{Mutex, watch};

use super::error::{ApiError, json_response};
use chladni_core::plate::photo::input::{self, PhotoError};
use chladni_media::vision::verify::{self, Check, Outcome, Verification};

/// The route a photo is posted to (and the last verification read from).
pub const ROUTE: &str = "/api/verify";
/// The last verification's figure.
pub(crate) const PHOTO_ROUTE: &str = "/api/verify/photo.png";
/// The largest photo taken: a 12 MP camera's JPEG is 3–8 MB, a 2 MP grey PNG about 2 MB.
pub const MAX_PHOTO_BYTES: usize = 16 * 1024 * 1024;
/// The content types a photo may be posted as.
pub(crate) const PHOTO_TYPES: [&str; 2] = ["image/png", "image/jpeg"];

/// What a photo is judged by.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The plan's predictions for the parts.
    pub check: Check,
    /// The plate's size (mm).
    pub size_mm: [f64; 2],
    /// The plate's corners in the camera's picture (px), when fixed; else found per photo.
    pub corners: Option<[[f64; 2]; 4]>,
}

/// The Modbus result register of the last verification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ResultCode {
    /// 0: no photo checked yet.
    #[default]
    None = 0,
    /// 1: every part found is as the plan predicts.
    Ok = 1,
    /// 2: at least one part is off or cannot be seen.
    Off = 2,
    /// 3: no part was found on the plate.
    Empty = 3,
    /// 4: the photo could not be examined (not a photo, no plate found in it, ...).
    Refused = 4,
}

impl ResultCode {
    /// The name in the JSON (`result`).
    pub const fn name(self) -> &'static str {
        match self {
            ResultCode::None => "none",
            ResultCode::Ok => "ok",
            ResultCode::Off => "off",
            ResultCode::Empty => "empty",
            ResultCode::Refused => "refused",
        }
    }
}

/// One verification as published.
#[derive(Debug, Clone)]
pub struct Published {
    /// Its number: 1 for the first photo this server checked.
    pub seq: u32,
    /// The result.
    pub code: ResultCode,
    /// Parts found.
    pub found: usize,
    /// Parts as planned.
    pub oriented: usize,
    /// `oriented / found`.
    pub success_rate: Option<f64>,
    /// The answer and the event's data.
    pub json: Value,
    /// The figure (PNG), for a photo that could be examined.
    pub png: Option<Bytes>,
}

/// "None" in the success-rate register.
pub const RATE_NONE: u16 = 0xFFFF;

struct Inner {
    setup: Option<Setup>,
    last: watch::Sender<Option<Arc<Published>>>,
    /// One photo at a time; holds the last sequence number.
    turn: Mutex<u32>,
}

/// The cell's verifier, shared by the HTTP and Modbus front ends.
#[derive(Clone)]
pub struct Verifier {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Verifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Verifier").field("enabled", &self.inner.setup.is_some()).finish()
    }
}

impl Verifier {
    /// A verifier judging photos by `setup`, or one that refuses them (`None`: serve was not
    /// given a plan).
    pub fn new(setup: Option<Setup>) -> Self {
        let (last, _) = watch::channel(None);
        Verifier { inner: Arc::new(Inner { setup, last, turn: Mutex::new(0) }) }
    }

    /// The last verification, if any.
    pub fn last(&self) -> Option<Arc<Published>> {
        self.inner.last.borrow().clone()
    }

    /// Each new verification.
    pub fn watch(&self) -> watch::Receiver<Option<Arc<Published>>> {
        self.inner.last.subscribe()
    }

    /// The Modbus input registers of the last verification, in address order: sequence
    /// number (low 16 bits; 0 none yet), result code, parts found, parts as planned, success
    /// rate in 0.1 % ([`RATE_NONE`] when none).
    pub fn registers(&self) -> [u16; 5] {
        let Some(p) = self.last() else { return [0, 0, 0, 0, RATE_NONE] };
        let sat = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
        let rate = p.success_rate.map_or(RATE_NONE, |r| (r * 1000.0).round() as u16);
        [p.seq as u16, p.code as u16, sat(p.found), sat(p.oriented), rate]
    }

    /// Examines a posted photo and publishes the result (also when the photo is refused).
    pub async fn verify(&self, photo: Bytes) -> Result<Arc<Published>, ApiError> {
        if self.inner.setup.is_none() {
            return Err(ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "not_set_up",
                "this cell checks no photos: start `chladni serve` with --verify-plan \
                          plan.json --verify-part P.json --verify-plate PLATE.toml",
            ));
        }
        let mut seq = self.inner.turn.lock().await;
        let inner = Arc::clone(&self.inner);
        let outcome = tokio::task::spawn_blocking(move || match &inner.setup {
            Some(setup) => examine(setup, &photo),
            None => Err(("not_set_up", String::new())),
        })
        .await
        .map_err(|e| {
            ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal",
                format!("examining the photo failed: {e}"),
            )
        })?;
        *seq = seq.wrapping_add(1);
        let published = Arc::new(publishable(*seq, outcome));
        self.inner.last.send_replace(Some(Arc::clone(&published)));
        Ok(published)
    }
}

/// The published form of an examination.
fn publishable(seq: u32, outcome: Result<(Verification, Bytes), (&str, String)>) -> Published {
    match outcome {
        Ok((v, png)) => {
            let code = match v.result {
                Outcome::Ok => ResultCode::Ok,
                Outcome::Off => ResultCode::Off,
                Outcome::Empty => ResultCode::Empty,
            };
            let mut json = serde_json::to_value(&v).unwrap_or_default();
            if let Value::Object(fields) = &mut json {
                fields.insert("seq".into(), seq.into());
                fields.insert("photo".into(), format!("{PHOTO_ROUTE}?seq={seq}").into());
            }
            let (found, oriented, success_rate) = (v.found, v.oriented, v.success_rate);
            Published { seq, code, found, oriented, success_rate, json, png: Some(png) }
        }
        Err((kind, message)) => Published {
            seq,
            code: ResultCode::Refused,
            found: 0,
            oriented: 0,
            success_rate: None,
            json: json!({"seq": seq, "result": ResultCode::Refused.name(), "error": kind,
                         "message": message, "found": 0, "oriented": 0, "success_rate": null}),
            png: None,
        },
    }
}

/// Decodes, locates and judges one photo: the verification and its figure (PNG), or the
/// refusal's name and message.
pub(crate) fn examine(
    setup: &Setup,
    photo: &[u8],
) -> Result<(Verification, Bytes), (&'static str, String)> {
    let name = Path::new("the posted photo");
    match image::guess_format(photo) {
        Ok(image::ImageFormat::Png | image::ImageFormat::Jpeg) => {}
        Ok(other) => {
            let message = format!("the posted photo is {other:?}: post a PNG or a JPEG");
            return Err(("not_a_photo", message));
        }
        Err(_) => {
            let message = format!(
                "the posted {} bytes are not a PNG or JPEG image: post the camera's picture",
                photo.len()
            );
            return Err(("not_a_photo", message));
        }
    }
    let img = input::read_bytes(photo, name).map_err(|e| match e {
        PhotoError::TooLarge { .. } => ("too_large", e.to_string()),
        PhotoError::Read { .. } => ("not_a_photo", e.to_string()),
    })?;
    let check = &setup.check;
    let (report, rectified) =
        chladni_media::vision::locate(&img, &check.templates, setup.size_mm, setup.corners)
            .map_err(|e| (e.name(), e.to_string()))?;
    let v = check.judge(&report);
    let fig = verify::draw(&rectified, &report, &v, &check.templates, setup.size_mm[1]);
    let mut png = Vec::new();
    fig.write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| ("figure", format!("cannot encode the figure: {e}")))?;
    Ok((v, Bytes::from(png)))
}

/// The guard's content-type rule for [`ROUTE`]: `image/png` or `image/jpeg` (415 otherwise).
pub fn check_photo_type(headers: &HeaderMap) -> Result<(), ApiError> {
    let given = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok());
    let essence = given.map(|t| t.split(';').next().unwrap_or("").trim().to_ascii_lowercase());
    if essence.as_deref().is_some_and(|e| PHOTO_TYPES.contains(&e)) {
        return Ok(());
    }
    Err(ApiError::new(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media_type",
        format!(
            "the body is {}: {ROUTE} takes the photo itself, `Content-Type: image/png` or \
             `image/jpeg`",
            given.map_or("sent without a Content-Type".to_owned(), |t| format!("'{t}'"))
        ),
    ))
}

/// The verification routes (behind the cell's guard, see [`super::http::router_with`]).
pub(crate) fn routes(verifier: Verifier) -> Router {
    Router::new()
        .route(ROUTE, get(last).post(post_photo))
        .route(PHOTO_ROUTE, get(figure))
        .with_state(verifier)
}

fn too_large(what: &str) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "too_large",
        format!(
            "the photo is {what}, over the {} MiB {ROUTE} takes: post a smaller picture (a few \
             MP is plenty)",
            MAX_PHOTO_BYTES / (1024 * 1024)
        ),
    )
}

async fn post_photo(
    State(verifier): State<Verifier>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ApiError> {
    let announced = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if let Some(n) = announced.filter(|&n| n > MAX_PHOTO_BYTES as u64) {
        return Err(too_large(&format!("{n} bytes")));
    }
    let photo = axum::body::to_bytes(body, MAX_PHOTO_BYTES)
        .await
        .map_err(|_| too_large("larger than that, or it did not arrive whole"))?;
    let published = verifier.verify(photo).await?;
    let status = match published.code {
        ResultCode::Refused => StatusCode::UNPROCESSABLE_ENTITY,
        _ => StatusCode::OK,
    };
    Ok(json_response(status, &published.json))
}

async fn last(State(verifier): State<Verifier>) -> Result<Response, ApiError> {
    match verifier.last() {
        Some(p) => Ok(json_response(StatusCode::OK, &p.json)),
        None => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no photo checked yet: POST one (image/png or image/jpeg) to {ROUTE}"),
        )),
    }
}

async fn figure(State(verifier): State<Verifier>) -> Result<Response, ApiError> {
    let Some(png) = verifier.last().and_then(|p| p.png.clone()) else {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no figure: no photo was examined yet (POST one to {ROUTE})"),
        ));
    };
    let mut response = (StatusCode::OK, png).into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    Ok(response)
}

/// The verification events of `/api/events`: the last one at once (if any), then each new
/// one, as `event: verify` with the published JSON.
pub fn events(
    last: watch::Receiver<Option<Arc<Published>>>,
) -> impl Stream<Item = Result<Event, Infallible>> {
    stream::unfold((last, true), |(mut last, first)| async move {
        if !first {
            last.changed().await.ok()?;
        }
        loop {
            let current = last.borrow_and_update().clone();
            if let Some(p) = current {
                let event = Event::default().event("verify").data(p.json.to_string());
                return Some((Ok(event), (last, false)));
            }
            last.changed().await.ok()?;
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_core::model::part::Part;
    use chladni_core::model::plan_file::PlanFile;

    fn setup() -> Setup {
        let tri = Part::new("tri".into(), vec![[0.0, 0.0], [36.0, 0.0], [0.0, 22.0]], vec![]);
        let plan = PlanFile {
            final_orientation_deg: Some(10.0),
            period_deg: Some(360.0),
            ..PlanFile::default()
        };
        let check = Check::new(&plan, &[tri.unwrap()], 5.0, 2.0).unwrap();
        Setup { check, size_mm: [300.0, 200.0], corners: None }
    }

    #[test]
    fn only_png_and_jpeg_bodies_pass_and_other_bytes_are_named() {
        let mut headers = HeaderMap::new();
        assert_eq!(
            check_photo_type(&headers).unwrap_err().status,
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        );
        for (t, ok) in [("image/png", true), ("IMAGE/JPEG; q=1", true), ("text/plain", false)] {
            headers.insert(header::CONTENT_TYPE, HeaderValue::from_str(t).unwrap());
            assert_eq!(check_photo_type(&headers).is_ok(), ok, "{t}");
        }
        let s = setup();
        assert_eq!(examine(&s, b"hello").unwrap_err().0, "not_a_photo");
        let mut gif = Vec::new();
        image::RgbaImage::new(4, 4)
            .write_to(&mut Cursor::new(&mut gif), image::ImageFormat::Gif)
            .unwrap();
        let (kind, message) = examine(&s, &gif).unwrap_err();
        assert_eq!(kind, "not_a_photo");
        assert!(message.contains("Gif") && message.contains("PNG or a JPEG"), "{message}");
        // A PNG of even grey: a photo, but no plate in it.
        let mut png = Vec::new();
        image::GrayImage::from_pixel(200, 150, image::Luma([128]))
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        assert_eq!(examine(&s, &png).unwrap_err().0, "no_plate");
    }

    #[tokio::test]
    async fn each_check_is_published_with_its_number_and_registers() {
        let v = Verifier::new(Some(setup()));
        assert_eq!(v.registers(), [0, 0, 0, 0, RATE_NONE]);
        let mut events = v.watch();
        let refused = v.verify(Bytes::from_static(b"not a photo")).await.unwrap();
        assert_eq!((refused.seq, refused.code), (1, ResultCode::Refused));
        assert_eq!(refused.json["error"], "not_a_photo");
        assert!(events.has_changed().unwrap());
        assert_eq!(events.borrow_and_update().as_ref().unwrap().seq, 1);
        assert_eq!(v.registers(), [1, 4, 0, 0, RATE_NONE]);
        let off = Verifier::new(None).verify(Bytes::new()).await.unwrap_err();
        assert_eq!(off.status, StatusCode::SERVICE_UNAVAILABLE);
        assert!(off.message.contains("--verify-plan"), "{}", off.message);
    }
}
