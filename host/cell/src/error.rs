//! The API's one error answer, [`ApiError`], shared by the routes ([`crate::http`]), the
//! guard in front of them ([`crate::guard`]) and the photo check ([`crate::verify`]).
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use chladni_device::client::DeviceError;
use chladni_media::shapes::failure::FailureJson;
use serde::Serialize;
use serde_json::Value;

use crate::CellError;

/// An API error: the HTTP status and the tool's one failure object, `{"error": kind,
/// "message": …}` (the CLI's `--json` shape, [`FailureJson`]) plus the fields its kind has.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    /// The HTTP status.
    pub status: StatusCode,
    /// The failure's snake_case name (docs/cell.md lists them).
    pub kind: &'static str,
    /// What went wrong, naming the value and the fix.
    pub message: String,
    /// The kind's own fields (`slot` for `bad_slot` and `no_plan`).
    pub fields: serde_json::Map<String, Value>,
}

impl ApiError {
    /// An error of `kind` with no fields of its own.
    pub fn new(status: StatusCode, kind: &'static str, message: impl Into<String>) -> Self {
        ApiError { status, kind, message: message.into(), fields: serde_json::Map::new() }
    }

    pub(crate) fn bad_request(message: impl Into<String>) -> Self {
        ApiError::new(StatusCode::BAD_REQUEST, "bad_input", message)
    }

    /// With one more field of its kind.
    fn with(mut self, key: &str, value: impl Into<Value>) -> Self {
        self.fields.insert(key.to_owned(), value.into());
        self
    }
}

/// The kind of an error answer the stack made (a limit, a timeout), from its status.
pub(crate) fn kind_of_status(status: StatusCode) -> &'static str {
    match status {
        StatusCode::PAYLOAD_TOO_LARGE => "too_large",
        StatusCode::GATEWAY_TIMEOUT | StatusCode::REQUEST_TIMEOUT => "timeout",
        StatusCode::SERVICE_UNAVAILABLE => "unavailable",
        s if s.is_client_error() => "bad_input",
        _ => "internal",
    }
}

impl From<CellError> for ApiError {
    fn from(e: CellError) -> Self {
        let message = e.to_string();
        match e {
            CellError::BadSlot { slot } => {
                ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "bad_slot", message)
                    .with("slot", slot)
            }
            CellError::NoPlan { slot, .. } => {
                ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "no_plan", message)
                    .with("slot", slot)
            }
            CellError::LinkDown { .. } => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "link_down", message)
            }
            CellError::Stopped => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "stopped", message)
            }
            CellError::QueueFull => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "queue_full", message)
            }
            CellError::Device(d) => {
                let (status, kind) = device_status(&d);
                ApiError::new(status, kind, message)
            }
        }
    }
}

/// The HTTP status and kind of a controller error.
fn device_status(e: &DeviceError) -> (StatusCode, &'static str) {
    match e {
        DeviceError::Refused(_)
        | DeviceError::StaleSweep { .. }
        | DeviceError::SweepIncomplete { .. } => (StatusCode::CONFLICT, "refused"),
        DeviceError::Open { .. }
        | DeviceError::Io(_)
        | DeviceError::Closed
        | DeviceError::Timeout { .. } => (StatusCode::SERVICE_UNAVAILABLE, "link_down"),
        DeviceError::Link(_)
        | DeviceError::Protocol { .. }
        | DeviceError::VersionMismatch { .. } => (StatusCode::BAD_GATEWAY, "link"),
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut body = self.fields;
        if let Ok(Value::Object(failure)) =
            serde_json::to_value(FailureJson::new(self.kind, &self.message))
        {
            body.extend(failure);
        }
        json_response(self.status, &body)
    }
}

/// A JSON response. Serializing the API's own types cannot fail; if it ever did, the client
/// gets a 500 naming it rather than a dropped connection.
pub(crate) fn json_response<T: Serialize>(status: StatusCode, value: &T) -> Response {
    let (status, body) = match serde_json::to_string(value) {
        Ok(body) => (status, body),
        Err(e) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            serde_json::json!(FailureJson::new(
                "internal",
                &format!("cannot encode the answer: {e}")
            ))
            .to_string(),
        ),
    };
    let mut response = (status, body).into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    // The status changes ten times a second: no cache may keep an answer.
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    response
}
