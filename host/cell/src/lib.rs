//! # chladni-cell
//!
//! The feeder in a cell: one process owns the controller link and serves it to a PLC or robot
//! controller and to people.
//!
//! - [`Cell`] (in [`owner`]) is the link's one owner: a thread that holds the
//!   [`DeviceClient`](chladni_device::client::DeviceClient) session, runs the commands sent to
//!   it (stop and clear-fault first), and polls the controller's status for everyone else.
//!   Front ends never talk to the link themselves, so a PLC and a browser at once never
//!   interleave frames, and a lost link shows as an error state, never as a stale "busy".
//! - The front ends (`chladni serve`) turn their protocol into [`Cell`] calls and its
//!   [`CellStatus`] into their registers or pages: [`modbus`] (Modbus TCP for a PLC, framed by
//!   [`mbap`]; the register map is in docs/cell.md) and [`http`] (the dashboard and JSON API
//!   for people, behind [`guard`]); [`verify`] checks photos of a run against its plan for
//!   both.
//! - [`net`] (accepting, connection caps, allow-lists) and [`ratelog`] (bounded logging) keep
//!   both front ends up under floods of connections and bad requests.

#![forbid(unsafe_code)]

pub mod error;
pub mod guard;
pub mod http;
pub mod mbap;
pub mod modbus;
pub mod net;
pub mod owner;
pub mod ratelog;
pub mod verify;

pub use owner::{Cell, CellError, CellState, CellStatus, OwnerEnd, RunStarted};

/// The line `chladni serve --json` prints when a front end listens: `{"<front end>":
/// address}`, with `"login"` (the URL carrying the token) for an HTTP front end behind one.
/// Keys in alphabetical order, as printed; a script waits for this line.
pub fn listening_json(front_end: &str, address: &str, login: Option<&str>) -> serde_json::Value {
    let mut line = serde_json::Map::new();
    line.insert(front_end.to_string(), address.into());
    if let Some(login) = login {
        line.insert("login".to_string(), login.into());
    }
    serde_json::Value::Object(line)
}
