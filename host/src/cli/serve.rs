//! `chladni serve`: the feeder in a cell. One process owns the controller link
//! ([`chladni::cell::Cell`]) and serves it through front ends: Modbus TCP for a PLC (`--modbus`)
//! and, from the HTTP front end, a dashboard (`--http`). It runs until Ctrl-C or SIGTERM; the
//! drive is left as it is (a run in progress goes on).
//!
//! Each listener is bound before anything is printed; port 0 picks a free port, and the line
//! printed per front end (`modbus listening on ADDR`, or `{"modbus": "ADDR"}` with `--json`)
//! names the address actually bound, so scripts and tests read it from the first lines.

use std::io::Write as _;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use chladni::cell::Cell;
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
        let cell = Cell::start(&self.port, "chladni serve");
        let mut front_ends = FrontEnds::new();
        if let Some(address) = self.modbus {
            let listener = bind(address, "--modbus").await?;
            self.announce("modbus", listener.local_addr()?)?;
            let registers = Registers::new(cell.clone());
            front_ends.spawn(async move { ("modbus", modbus::serve(listener, registers).await) });
        }
        // --http: wired by the HTTP front end (bind, announce and spawn as --modbus does).
        let (stop_tx, mut stop_rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
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
    fn announce(&self, name: &str, address: SocketAddr) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        if self.json {
            writeln!(out, "{}", serde_json::json!({ name: address.to_string() }))?;
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
