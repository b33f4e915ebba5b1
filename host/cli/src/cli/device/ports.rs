//! `chladni device list`: the serial ports of this machine ([`chladni_device::ports`]),
//! as a table or as their JSON shape ([`PortsJson`]).

use std::process::ExitCode;

use chladni_device::json::{PortJson, PortsJson};
use chladni_device::ports::available;

use super::render::print_json;

/// `list`.
pub fn list(json: bool) -> anyhow::Result<ExitCode> {
    let ports: Vec<PortJson> = available()?.iter().map(PortJson::from).collect();
    if json {
        print_json(&PortsJson { ports })?;
        return Ok(ExitCode::SUCCESS);
    }
    if ports.is_empty() {
        println!(
            "no serial ports found (the emulator's link is tcp://…, printed by `chladni emulator`)"
        );
    }
    for p in &ports {
        let ids = match (&p.vid, &p.pid) {
            (Some(v), Some(d)) => format!("{v}:{d}"),
            _ => "-".to_string(),
        };
        let product = p.product.as_deref().unwrap_or("");
        let note = match p.role {
            Some("controller") => format!("  <- controller: --port {}", p.name),
            Some(_) => "  <- ST-LINK console (firmware log; not the link)".to_string(),
            None => String::new(),
        };
        println!("{:<20} {:<9} {:<9} {product}{note}", p.name, p.kind, ids);
    }
    Ok(ExitCode::SUCCESS)
}
