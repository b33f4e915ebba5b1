//! `chladni serve`: the feeder in a cell. One process owns the controller link
//! ([`chladni_cell::Cell`]) and serves it through front ends: Modbus TCP for a PLC (`--modbus`,
//! [`chladni_cell::modbus`]) and a dashboard with a JSON API for people (`--http`,
//! [`chladni_cell::http`]). It runs until Ctrl-C or SIGTERM; the drive is left as it is (a run
//! in progress goes on).
//!
//! Each listener is bound before anything is printed; port 0 picks a free port, and the line
//! printed per front end (`modbus listening on ADDR`, `http listening on http://ADDR/`, or
//! `{"modbus": "ADDR"}`, `{"http": "http://ADDR/"}` with `--json`) names the address actually
//! bound, so scripts and tests read it from the first lines. With a token (`--token-file`) the
//! HTTP line is the dashboard's login URL, `http://ADDR/?token=TOKEN` (`--json`: `{"http":
//! "http://ADDR/", "login": "http://ADDR/?token=TOKEN"}`).
//!
//! What is refused at start, naming the fix: HTTP beyond loopback without `--token-file` or
//! `--no-auth`; Modbus beyond loopback without `--modbus-allow` (Modbus has no
//! authentication); an allow-host or allow-origin that is not a bare name or origin.

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use chladni_cell::guard::{self, Access};
use chladni_cell::modbus::{self, Registers};
use chladni_cell::net::{self, Caps, Cidr};
use chladni_cell::verify::{Setup, Verifier};
use chladni_cell::{Cell, http};
use chladni_device::client::{DEFAULT_TIMEOUT, RELEASE_TIMEOUT};
use chladni_shared::icd::link::OWNER_LEASE_MS;
use clap::Args;
use tokio::net::TcpListener;
use tokio::task::JoinSet;

use super::InputError;

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// The controller's link: a serial device or tcp://HOST:PORT (the emulator).
    #[arg(long)]
    port: String,
    /// Serve the Modbus TCP register map (docs/cell.md) on ADDR:PORT, e.g. 0.0.0.0:5020
    /// (port 0: a free port, printed).
    #[arg(long, value_name = "ADDR:PORT")]
    modbus: Option<SocketAddr>,
    /// Serve the HTTP dashboard and API on ADDR:PORT, e.g. 127.0.0.1:8080 (port 0: a free
    /// port, printed).
    #[arg(long, value_name = "ADDR:PORT")]
    http: Option<SocketAddr>,
    /// A host name (besides IP addresses and localhost) under which browsers may reach the
    /// HTTP front end, e.g. cell-7.plant.example; repeat for more.
    #[arg(long, value_name = "NAME")]
    http_allow_host: Vec<String>,
    /// An origin (besides the server's own) whose pages may send commands, e.g.
    /// https://hmi.plant.example; repeat for more.
    #[arg(long, value_name = "ORIGIN")]
    http_allow_origin: Vec<String>,
    /// Require the token in FILE for HTTP (created with a random token, mode 0600, when
    /// missing); needed when --http is not on loopback.
    #[arg(long, value_name = "FILE", conflicts_with = "no_auth")]
    token_file: Option<PathBuf>,
    /// Serve HTTP beyond loopback without a token (only on a network you trust).
    #[arg(long)]
    no_auth: bool,
    /// A client network allowed to use Modbus, e.g. 192.168.10.0/24 or 192.168.10.7; repeat
    /// for more (default: loopback only).
    #[arg(long, value_name = "CIDR")]
    modbus_allow: Vec<Cidr>,
    /// How many Modbus clients may be connected at once; one more is refused.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u16).range(1..))]
    modbus_clients: u16,
    /// Print the listening addresses as JSON objects, one a line.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    verify: VerifyServeArgs,
}

/// What `POST /api/verify` checks photos against (docs/cell.md, "Verifying a run from a
/// photo"); without --verify-plan the route refuses photos.
#[derive(Debug, Args)]
struct VerifyServeArgs {
    /// The plan whose result photos are checked against (chladni plan --out).
    #[arg(long, value_name = "plan.json", requires_all = ["verify_part", "verify_plate"])]
    verify_plan: Option<PathBuf>,
    /// The part(s) the plan was made for, in its order; repeat for several.
    #[arg(long, value_name = "FILE", requires = "verify_plan")]
    verify_part: Vec<PathBuf>,
    /// The plate the plan was made for (TOML).
    #[arg(long, value_name = "PLATE.toml", requires = "verify_plan")]
    verify_plate: Option<PathBuf>,
    /// The plate's corners in the camera's picture (px, as for `chladni locate`); found in
    /// each photo when not given.
    #[arg(
        long,
        num_args = 8,
        allow_negative_numbers = true,
        requires = "verify_plan",
        value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"]
    )]
    verify_corners: Option<Vec<f64>>,
    /// Orientation tolerance of a part as planned (deg).
    #[arg(long, value_name = "D", default_value_t = chladni_media::vision::verify::DEFAULT_TOL_DEG)]
    verify_tol_deg: f64,
    /// Position tolerance, where the plan fixes a position (mm).
    #[arg(long, value_name = "D", default_value_t = chladni_media::vision::verify::DEFAULT_TOL_MM)]
    verify_tol_mm: f64,
}

impl VerifyServeArgs {
    /// The verifier: the plan, parts and plate loaded and checked now, so that a bad file is
    /// refused at start (exit 2) rather than at the first photo.
    fn verifier(&self) -> anyhow::Result<Verifier> {
        let (Some(plan), Some(plate)) = (&self.verify_plan, &self.verify_plate) else {
            return Ok(Verifier::new(None));
        };
        let (size_mm, check) = super::verify::load_check(
            plan,
            &self.verify_part,
            plate,
            (self.verify_tol_deg, self.verify_tol_mm),
        )
        .map_err(|f| InputError(format!("--verify-plan: {:#}", f.error)))?;
        let corners = self
            .verify_corners
            .as_deref()
            .map(|c| [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]]);
        Ok(Verifier::new(Some(Setup { check, size_mm, corners })))
    }
}

/// How long a stopping server waits for the link owner to release the controller: the request
/// in flight (at most one answer's timeout), then the release, and 0.7 s for the thread to be
/// scheduled on a loaded machine (4 s in all).
const OWNER_END_LIMIT: Duration =
    DEFAULT_TIMEOUT.saturating_add(RELEASE_TIMEOUT).saturating_add(Duration::from_millis(700));

/// What `serve` checked of its arguments before it opened the link.
struct Checked {
    access: Access,
    modbus: modbus::Options,
    verifier: Verifier,
    caps: Caps,
}

/// A front end's task: it runs until the process stops, or ends with why it failed.
type FrontEnds = JoinSet<(&'static str, std::io::Result<()>)>;

impl ServeArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        if self.modbus.is_none() && self.http.is_none() {
            return Err(InputError(
                "chladni serve needs a front end: give --modbus ADDR:PORT (e.g. \
                 127.0.0.1:5020) and/or --http ADDR:PORT (e.g. 127.0.0.1:8080)"
                    .into(),
            )
            .into());
        }
        // Every input checked before the cell opens the link: a refused start touches nothing.
        let checked = Checked {
            access: self.access()?,
            modbus: self.modbus_options()?,
            verifier: self.verify.verifier()?,
            caps: Caps::from_limit(net::open_file_limit(), usize::from(self.modbus_clients)),
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .context("starting the async runtime")?;
        let cell = Cell::start(&self.port, &format!("chladni serve (pid {})", std::process::id()));
        let owner_end = cell.owner_end();
        let result = runtime.block_on(self.serve(cell, checked));
        // Open connections are dropped with the runtime (nothing in them needs finishing), and
        // with them the last handles on the cell.
        runtime.shutdown_timeout(Duration::from_secs(1));
        // The owner releases the controller as it ends: without this wait the process could
        // exit first, and the next program would find the controller held for the lease.
        if !owner_end.wait(OWNER_END_LIMIT) {
            eprintln!(
                "chladni serve: the controller link did not close within {:.1} s: the controller \
                 stays held by this server for its lease ({:.1} s)",
                OWNER_END_LIMIT.as_secs_f64(),
                f64::from(OWNER_LEASE_MS) / 1000.0
            );
        }
        result
    }

    async fn serve(&self, cell: Cell, checked: Checked) -> anyhow::Result<ExitCode> {
        let Checked { access, modbus: modbus_options, verifier, caps } = checked;
        // Before any address is printed: whoever reads it may signal at once (and `ctrlc`
        // takes one handler per process, for every front end).
        let (stop_tx, mut stop_rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let mut front_ends = FrontEnds::new();
        if let Some(address) = self.modbus {
            let listener = bind(address, "--modbus").await?;
            self.announce("modbus", listener.local_addr()?.to_string(), None)?;
            let registers = Registers::new(cell.clone()).with_verifier(verifier.clone());
            let options = modbus::Options { clients: caps.modbus, ..modbus_options };
            front_ends.spawn(async move {
                ("modbus", modbus::serve(listener, registers, options).await)
            });
        }
        if let Some(address) = self.http {
            let listener = bind(address, "--http").await?;
            let url = url_of(listener.local_addr()?);
            let login = access.token.as_ref().map(|t| format!("{url}?token={t}"));
            self.announce("http", url, login)?;
            let cell = cell.clone();
            let options = http::Options {
                access,
                connections: caps.http,
                overflow: caps.http_overflow,
                verifier,
            };
            front_ends.spawn(async move { ("http", http::serve(cell, listener, options).await) });
        }
        tokio::select! {
            _ = stop_rx.recv() => {
                eprintln!("chladni serve: stopping (the drive is left as it is)");
                Ok(ExitCode::SUCCESS)
            }
            Some(ended) = front_ends.join_next() => {
                let (name, result) = ended.context("a front end's task panicked")?;
                let reason = match result {
                    Ok(()) => "it stopped".to_owned(),
                    Err(e) => e.to_string(),
                };
                anyhow::bail!("the {name} front end ended: {reason}")
            }
        }
    }

    /// Prints where a front end listens, and flushes: a script waits for this line.
    fn announce(&self, name: &str, address: String, login: Option<String>) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        match (self.json, login) {
            (true, login) => {
                writeln!(
                    out,
                    "{}",
                    chladni_cell::listening_json(name, &address, login.as_deref())
                )?;
            }
            (false, login) => {
                writeln!(out, "{name} listening on {}", login.unwrap_or(address))?;
            }
        }
        out.flush()?;
        Ok(())
    }

    /// Who may use HTTP: the token (required beyond loopback unless --no-auth), the hosts and
    /// origins allowed.
    fn access(&self) -> anyhow::Result<Access> {
        let beyond_loopback = self.http.is_some_and(|a| !a.ip().is_loopback());
        if beyond_loopback && self.token_file.is_none() && !self.no_auth {
            let address = self.http.map(|a| a.to_string()).unwrap_or_default();
            return Err(InputError(format!(
                "--http {address} is reachable from other machines, and whoever reaches it can \
                 run the shaker: give --token-file FILE (a random token is written there when it \
                 is missing; the login URL is printed), or --no-auth on a network you trust, or \
                 bind 127.0.0.1"
            ))
            .into());
        }
        let token = match &self.token_file {
            Some(path) => Some(guard::load_or_create_token(path)?),
            None => None,
        };
        let hosts =
            self.http_allow_host.iter().map(|h| allowed_host(h)).collect::<Result<_, _>>()?;
        let origins =
            self.http_allow_origin.iter().map(|o| allowed_origin(o)).collect::<Result<_, _>>()?;
        Ok(Access { hosts, origins, token })
    }

    /// The Modbus allow-list (default loopback), refused when it cannot match the bind.
    fn modbus_options(&self) -> anyhow::Result<modbus::Options> {
        if let Some(address) = self.modbus
            && !address.ip().is_loopback()
            && self.modbus_allow.is_empty()
        {
            return Err(InputError(format!(
                "--modbus {address} listens beyond loopback, but Modbus has no authentication \
                 and only loopback clients are allowed by default: give the PLC's address or \
                 network with --modbus-allow (e.g. --modbus-allow 192.168.10.0/24), or bind \
                 127.0.0.1"
            ))
            .into());
        }
        let allow =
            if self.modbus_allow.is_empty() { Cidr::loopback() } else { self.modbus_allow.clone() };
        let clients = usize::from(self.modbus_clients);
        Ok(modbus::Options { allow, clients, idle: modbus::IDLE_TIMEOUT })
    }
}

/// A `--http-allow-host` value: a bare host name, lowercase.
fn allowed_host(given: &str) -> Result<String, InputError> {
    let name = given.trim().to_ascii_lowercase();
    let bare =
        !name.is_empty() && name.bytes().all(|b| b.is_ascii_alphanumeric() || b"-.".contains(&b));
    if bare {
        Ok(name)
    } else {
        Err(InputError(format!(
            "--http-allow-host '{given}' is not a host name: give the name alone, without scheme \
             or port, e.g. --http-allow-host cell-7.plant.example"
        )))
    }
}

/// A `--http-allow-origin` value: `http(s)://host[:port]`, lowercase, no path.
fn allowed_origin(given: &str) -> Result<String, InputError> {
    let origin = given.trim().trim_end_matches('/').to_ascii_lowercase();
    let rest = origin.strip_prefix("http://").or_else(|| origin.strip_prefix("https://"));
    match rest {
        Some(host) if !host.is_empty() && !host.contains('/') => Ok(origin),
        _ => Err(InputError(format!(
            "--http-allow-origin '{given}' is not an origin: give scheme and host (and port), \
             e.g. --http-allow-origin https://hmi.plant.example"
        ))),
    }
}

/// Binds a front end's listener; the error names the address, the flag and the fix.
pub async fn bind(address: SocketAddr, flag: &str) -> anyhow::Result<TcpListener> {
    TcpListener::bind(address).await.map_err(|e| {
        let fix = match e.kind() {
            std::io::ErrorKind::PermissionDenied if address.port() < 1024 => format!(
                "ports below 1024 (Modbus's 502, HTTP's 80) need root or CAP_NET_BIND_SERVICE; \
                 use a port from 1024 on, e.g. {flag} {}",
                SocketAddr::new(address.ip(), if flag == "--modbus" { 5020 } else { 8080 })
            ),
            std::io::ErrorKind::AddrInUse => {
                "another program listens there: stop it or choose another port".to_owned()
            }
            std::io::ErrorKind::AddrNotAvailable => {
                "this machine has no such address: use 127.0.0.1, 0.0.0.0 or one of its own"
                    .to_owned()
            }
            _ => "check the address".to_owned(),
        };
        anyhow::anyhow!("cannot listen on {address} ({flag}): {e}; {fix}")
    })
}

/// The address to browse: a server on every interface is reached here on loopback.
fn url_of(addr: SocketAddr) -> String {
    let shown = match addr {
        SocketAddr::V4(a) if a.ip().is_unspecified() => {
            SocketAddr::from(([127, 0, 0, 1], a.port()))
        }
        SocketAddr::V6(a) if a.ip().is_unspecified() => {
            SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, a.port()))
        }
        a => a,
    };
    format!("http://{shown}/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allowed_hosts_and_origins_are_checked_and_lowercased() {
        assert_eq!(allowed_host("Cell-7.Plant").unwrap(), "cell-7.plant");
        assert!(allowed_host("http://cell").unwrap_err().0.contains("without scheme"));
        assert!(allowed_host("cell:80").is_err());
        assert_eq!(allowed_origin("HTTPS://hmi.plant:8443/").unwrap(), "https://hmi.plant:8443");
        assert!(allowed_origin("hmi.plant").unwrap_err().0.contains("https://hmi"));
        assert!(allowed_origin("https://hmi.plant/page").is_err());
    }

    #[test]
    fn the_url_of_a_server_on_every_interface_is_on_loopback() {
        assert_eq!(url_of("0.0.0.0:8080".parse().unwrap()), "http://127.0.0.1:8080/");
        assert_eq!(url_of("[::]:81".parse().unwrap()), "http://[::1]:81/");
        assert_eq!(url_of("192.0.2.7:80".parse().unwrap()), "http://192.0.2.7:80/");
    }
}
