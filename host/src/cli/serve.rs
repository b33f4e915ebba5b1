//! `chladni serve`: one process owns the controller link ([`Cell`]) and serves it to the cell,
//! in the foreground until Ctrl-C or SIGTERM. This version serves `--http` (the dashboard and
//! JSON API, [`chladni::cell::http`]); `--modbus` comes with the Modbus front end.

use std::io::Write;
use std::net::SocketAddr;
use std::process::ExitCode;

use anyhow::Context;
use chladni::cell::{Cell, http};
use clap::Args;
use tokio::net::TcpListener;

use super::InputError;

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Serial device (e.g. /dev/ttyACM0) or tcp://HOST:PORT of the controller.
    #[arg(long, short)]
    port: String,
    /// Modbus TCP server address, e.g. 0.0.0.0:502 (port 0: a free port, printed).
    #[arg(long, value_name = "ADDR:PORT")]
    modbus: Option<SocketAddr>,
    /// Web dashboard and JSON API address, e.g. 127.0.0.1:8080 (port 0: a free port, printed).
    #[arg(long, value_name = "ADDR:PORT")]
    http: Option<SocketAddr>,
    /// Print the listening addresses as one JSON object.
    #[arg(long)]
    json: bool,
}

impl ServeArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        if self.modbus.is_some() {
            return Err(InputError("--modbus is not in this build: serve --http".into()).into());
        }
        let Some(http_addr) = self.http else {
            return Err(InputError(
                "nothing to serve: give --http ADDR:PORT (e.g. --http 127.0.0.1:8080)".into(),
            )
            .into());
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .context("starting the async runtime")?;
        let listener = runtime
            .block_on(TcpListener::bind(http_addr))
            .with_context(|| format!("cannot listen for HTTP on {http_addr}"))?;
        // Before the address is printed: whoever reads it may signal at once.
        let (stop_tx, mut stop_rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let url = url_of(listener.local_addr()?);
        if self.json {
            println!("{}", serde_json::json!({ "http": url }));
        } else {
            println!("http listening on {url}");
        }
        std::io::stdout().flush()?;
        let cell = Cell::start(&self.port, &format!("chladni serve (pid {})", std::process::id()));
        runtime.block_on(async {
            tokio::select! {
                served = http::serve(cell, listener) => served.context("serving HTTP"),
                _ = stop_rx.recv() => {
                    eprintln!("stopping chladni serve");
                    Ok(())
                }
            }
        })?;
        Ok(ExitCode::SUCCESS)
    }
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
