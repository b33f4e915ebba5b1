//! `chladni serve`: the feeder in a cell. One process owns the controller link
//! ([`chladni::cell::Cell`]) and serves it through front ends: Modbus TCP for a PLC (`--modbus`,
//! [`chladni::cell::modbus`]) and a dashboard with a JSON API for people (`--http`,
//! [`chladni::cell::http`]). It runs until Ctrl-C or SIGTERM; the drive is left as it is (a run
//! in progress goes on).
//!
//! Each listener is bound before anything is printed; port 0 picks a free port, and the line
//! printed per front end (`modbus listening on ADDR`, `http listening on http://ADDR/`, or
//! `{"modbus": "ADDR"}`, `{"http": "http://ADDR/"}` with `--json`) names the address actually
//! bound, so scripts and tests read it from the first lines.

use std::io::Write as _;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use chladni::cell::Cell;
use chladni::cell::http;
use chladni::cell::modbus::{self, Registers};
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
    /// Print the listening addresses as JSON objects, one a line.
    #[arg(long)]
    json: bool,
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
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .context("starting the async runtime")?;
        let result = runtime.block_on(self.serve());
        // Open connections are dropped with the runtime; nothing in them needs finishing.
        runtime.shutdown_timeout(Duration::from_secs(1));
        result
    }

    async fn serve(&self) -> anyhow::Result<ExitCode> {
        let cell = Cell::start(&self.port, &format!("chladni serve (pid {})", std::process::id()));
        // Before any address is printed: whoever reads it may signal at once (and `ctrlc`
        // takes one handler per process, for every front end).
        let (stop_tx, mut stop_rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let mut front_ends = FrontEnds::new();
        if let Some(address) = self.modbus {
            let listener = bind(address, "--modbus").await?;
            self.announce("modbus", listener.local_addr()?.to_string())?;
            let registers = Registers::new(cell.clone());
            front_ends.spawn(async move { ("modbus", modbus::serve(listener, registers).await) });
        }
        if let Some(address) = self.http {
            let listener = bind(address, "--http").await?;
            self.announce("http", url_of(listener.local_addr()?))?;
            let cell = cell.clone();
            front_ends.spawn(async move { ("http", http::serve(cell, listener).await) });
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
    fn announce(&self, name: &str, address: String) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        if self.json {
            writeln!(out, "{}", serde_json::json!({ name: address }))?;
        } else {
            writeln!(out, "{name} listening on {address}")?;
        }
        out.flush()?;
        Ok(())
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
    fn the_url_of_a_server_on_every_interface_is_on_loopback() {
        assert_eq!(url_of("0.0.0.0:8080".parse().unwrap()), "http://127.0.0.1:8080/");
        assert_eq!(url_of("[::]:81".parse().unwrap()), "http://[::1]:81/");
        assert_eq!(url_of("192.0.2.7:80".parse().unwrap()), "http://192.0.2.7:80/");
    }
}
