//! The HTTP front end's protection against the operator's own browser and the network: what
//! stops a web page from elsewhere, a DNS-rebinding page and a client without the token
//! (docs/cell.md has the threat table).
//!
//! - Host: every request must name this server: an IP literal, `localhost` (or a name under
//!   it), or a name given with `--http-allow-host`; else 421. A rebinding page reaches the
//!   server under the attacker's name, so it is refused before any route runs.
//! - State changes (every method but GET and HEAD) must carry an `application/json` body
//!   (else 415): a page from another origin can send such a body only after a CORS preflight,
//!   which this server never grants; and an `Origin` header, when present, must be this
//!   server's own (`http://` + its Host) or one given with `--http-allow-origin` (else 403).
//!   The photo route takes `image/png` or `image/jpeg` instead ([`super::verify`]), types a
//!   page from another origin can send no more freely than JSON.
//! - Token (when the server has one): `Authorization: Bearer TOKEN`, or the cookie the
//!   dashboard's login URL (`/?token=TOKEN`) sets (HttpOnly, SameSite=Strict: page scripts
//!   cannot read it, other sites' requests do not carry it); else 401.
//! - Headers: more than [`MAX_HEADERS`] or [`MAX_HEADER_BYTES`] in all is 431, as JSON.
//!
//! Every refusal is JSON, `{"error": "..."}` naming what was refused and the fix.

use std::fs::OpenOptions;
use std::io::{Read as _, Write as _};
use std::os::unix::fs::{OpenOptionsExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;

/// The most header lines a request may carry.
pub const MAX_HEADERS: usize = 64;
/// The most bytes of header names and values a request may carry.
pub const MAX_HEADER_BYTES: usize = 8 * 1024;
/// The cookie the login URL sets.
pub(crate) const COOKIE: &str = "chladni_token";

/// Who may use the HTTP front end.
#[derive(Debug, Clone, Default)]
pub struct Access {
    /// Host names accepted besides IP literals and `localhost` (lowercase, no port).
    pub hosts: Vec<String>,
    /// Origins accepted besides the server's own (`scheme://host[:port]`, lowercase).
    pub origins: Vec<String>,
    /// The token every request must present; `None`: no authentication.
    pub token: Option<String>,
}

fn refused(status: StatusCode, message: String) -> ApiError {
    let kind = match status {
        StatusCode::UNAUTHORIZED => "unauthorized",
        StatusCode::FORBIDDEN => "forbidden",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        StatusCode::MISDIRECTED_REQUEST => "unknown_host",
        _ => "bad_input",
    };
    ApiError::new(status, kind, message)
}

/// The middleware: every request passes the checks in the module doc, in that order.
pub async fn check(State(access): State<Arc<Access>>, request: Request, next: Next) -> Response {
    if let Err(refusal) = check_request(&access, &request) {
        let unauthorized = refusal.status == StatusCode::UNAUTHORIZED;
        let mut response = refusal.into_response();
        if unauthorized {
            response
                .headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        return response;
    }
    if let Some(token) = &access.token
        && request.uri().path() == "/"
        && let Some(given) = query_token(request.uri().query())
    {
        return login(token, &given);
    }
    next.run(request).await
}

fn check_request(access: &Access, request: &Request) -> Result<(), ApiError> {
    check_headers(request.headers())?;
    let host = check_host(access, request.headers())?;
    if let Some(token) = &access.token {
        let login = request.uri().path() == "/" && query_token(request.uri().query()).is_some();
        if !login && !authorized(token, request.headers()) {
            return Err(refused(
                StatusCode::UNAUTHORIZED,
                "this server needs its token: send `Authorization: Bearer TOKEN` (the token is \
                 in the --token-file), or open the login URL `chladni serve` printed at start"
                    .into(),
            ));
        }
    }
    if !matches!(*request.method(), Method::GET | Method::HEAD) {
        check_origin(access, request.headers(), &host)?;
        if request.uri().path() == super::verify::ROUTE {
            super::verify::check_photo_type(request.headers())?;
        } else {
            check_json_body(request.headers())?;
        }
    }
    Ok(())
}

fn check_headers(headers: &HeaderMap) -> Result<(), ApiError> {
    let bytes: usize = headers.iter().map(|(n, v)| n.as_str().len() + v.len()).sum();
    if headers.len() > MAX_HEADERS || bytes > MAX_HEADER_BYTES {
        return Err(refused(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            format!(
                "the request has {} headers of {bytes} bytes: at most {MAX_HEADERS} headers of \
                 {MAX_HEADER_BYTES} bytes in all are taken",
                headers.len()
            ),
        ));
    }
    Ok(())
}

/// The Host's name (lowercase, without the port) if it is acceptable.
fn check_host(access: &Access, headers: &HeaderMap) -> Result<String, ApiError> {
    let Some(value) = headers.get(header::HOST).and_then(|v| v.to_str().ok()) else {
        return Err(refused(
            StatusCode::MISDIRECTED_REQUEST,
            "the request names no host: send a Host header with this server's address".into(),
        ));
    };
    let host = value.to_ascii_lowercase();
    if host_allowed(access, host_name(&host)) {
        Ok(host)
    } else {
        Err(refused(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "this server does not answer for host '{value}': use its address or \
                 localhost, or allow the name with --http-allow-host {}",
                host_name(&host)
            ),
        ))
    }
}

/// The name of a Host value: `[::1]:80` → `::1`, `cell.local:8080` → `cell.local`.
pub(crate) fn host_name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
        _ => host,
    }
}

/// IP literals (a rebinding page reaches the server by a name, never by an address),
/// `localhost` and its subdomains, and the names allowed.
pub(crate) fn host_allowed(access: &Access, name: &str) -> bool {
    name.parse::<std::net::IpAddr>().is_ok()
        || name == "localhost"
        || name.ends_with(".localhost")
        || access.hosts.iter().any(|h| h == name)
}

fn check_origin(access: &Access, headers: &HeaderMap, host: &str) -> Result<(), ApiError> {
    let Some(origin) = headers.get(header::ORIGIN) else { return Ok(()) };
    let text = origin.to_str().unwrap_or("(not text)");
    let lower = text.to_ascii_lowercase();
    if lower == format!("http://{host}") || access.origins.contains(&lower) {
        return Ok(());
    }
    Err(refused(
        StatusCode::FORBIDDEN,
        format!(
            "requests from origin '{text}' may not change anything here: only this server's own \
             pages may (http://{host}); to let another site's pages command the cell, give \
             --http-allow-origin {text}"
        ),
    ))
}

fn check_json_body(headers: &HeaderMap) -> Result<(), ApiError> {
    let given = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok());
    let essence = given.map(|t| t.split(';').next().unwrap_or("").trim().to_ascii_lowercase());
    if essence.as_deref() == Some("application/json") {
        return Ok(());
    }
    Err(refused(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        format!(
            "the body is {}: commands take `Content-Type: application/json` (send {{}} when \
             there is nothing to say)",
            given.map_or("sent without a Content-Type".to_owned(), |t| format!("'{t}'"))
        ),
    ))
}

fn query_token(query: Option<&str>) -> Option<String> {
    query?.split('&').find_map(|pair| pair.strip_prefix("token=")).map(str::to_owned)
}

fn authorized(token: &str, headers: &HeaderMap) -> bool {
    let bearer = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .is_some_and(|given| same(token, given.trim()));
    bearer
        || headers.get_all(header::COOKIE).iter().filter_map(|v| v.to_str().ok()).any(|v| {
            v.split(';')
                .filter_map(|c| c.trim().strip_prefix(COOKIE)?.strip_prefix('='))
                .any(|given| same(token, given))
        })
}

/// Compares without stopping at the first difference (no timing hint about the token).
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// `/?token=…`: the cookie and a redirect to the page, or 401 for a wrong token.
fn login(token: &str, given: &str) -> Response {
    if !same(token, given) {
        let message = "the token in the URL is not this server's: open the URL `chladni serve` \
                       printed at start";
        return refused(StatusCode::UNAUTHORIZED, message.into()).into_response();
    }
    let cookie = format!("{COOKIE}={token}; HttpOnly; SameSite=Strict; Path=/");
    let mut response = StatusCode::SEE_OTHER.into_response();
    let headers = response.headers_mut();
    headers.insert(header::LOCATION, HeaderValue::from_static("/"));
    if let Ok(value) = HeaderValue::from_str(&cookie) {
        headers.insert(header::SET_COOKIE, value);
    }
    response
}

/// Why the token file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    /// Reading or creating the file failed.
    #[error("cannot use the token file {path}: {source}; check the path and its directory")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Others than the owner may read the file.
    #[error(
        "the token file {path} may be read by others (mode {mode:o}): `chmod 600 {path}`, or \
         delete it to have a new one made"
    )]
    Readable {
        /// The file.
        path: String,
        /// Its permission bits.
        mode: u32,
    },
    /// The file holds too short a token.
    #[error(
        "the token file {path} holds {len} characters: a token has at least 16 (delete the \
         file to have a new one made)"
    )]
    TooShort {
        /// The file.
        path: String,
        /// The token's length.
        len: usize,
    },
}

/// The token in `path`, made (32 random bytes, hex, mode 0600) when the file is missing.
pub fn load_or_create_token(path: &Path) -> Result<String, TokenError> {
    let io = |source| TokenError::Io { path: path.to_owned(), source };
    match OpenOptions::new().write(true).create_new(true).mode(0o600).open(path) {
        Ok(mut file) => {
            let token = random_token().map_err(io)?;
            writeln!(file, "{token}").map_err(io)?;
            return Ok(token);
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io(e)),
    }
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mode = file.metadata().map_err(io)?.permissions().mode() & 0o777;
    let shown = path.display().to_string();
    if mode & 0o077 != 0 {
        return Err(TokenError::Readable { path: shown, mode });
    }
    let mut text = String::new();
    file.read_to_string(&mut text).map_err(io)?;
    let token = text.trim().to_owned();
    if token.len() < 16 || !token.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(TokenError::TooShort { path: shown, len: token.len() });
    }
    Ok(token)
}

/// 32 bytes from the kernel's random source, as hex.
fn random_token() -> std::io::Result<String> {
    let mut bytes = [0u8; 32];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_are_ip_literals_localhost_or_allowed_names() {
        let access = Access { hosts: vec!["cell-7.plant".into()], ..Access::default() };
        for ok in ["127.0.0.1:8080", "[::1]:80", "localhost:1", "LOCALHOST", "10.1.2.3"] {
            let lower = ok.to_ascii_lowercase();
            assert!(host_allowed(&access, host_name(&lower)), "{ok}");
        }
        assert!(host_allowed(&access, host_name("cell-7.plant:8080")));
        for bad in ["evil.example:8080", "cell-7.plant.evil.example", "127.0.0.1.nip.io"] {
            assert!(!host_allowed(&access, host_name(bad)), "{bad}");
        }
    }

    #[test]
    fn a_token_file_is_made_private_and_read_back() {
        let dir = std::env::temp_dir().join(format!("chladni-token-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("token");
        let _ = std::fs::remove_file(&path);
        let made = load_or_create_token(&path).unwrap();
        assert_eq!(made.len(), 64);
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(load_or_create_token(&path).unwrap(), made);
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = load_or_create_token(&path).unwrap_err().to_string();
        assert!(e.contains("chmod 600"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn tokens_compare_whole() {
        assert!(same("abcdef0123456789", "abcdef0123456789"));
        assert!(!same("abcdef0123456789", "abcdef012345678"));
        assert!(!same("abcdef0123456789", "abcdef0123456780"));
    }
}
