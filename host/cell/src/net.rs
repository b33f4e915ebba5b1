//! What both front ends need from the network layer: accepting that never ends the server, a
//! connection cap below the process's open-file limit, and client allow-lists by CIDR.
//!
//! Why a cap per front end: every connection is a file descriptor, and at the process's
//! open-file limit `accept` fails (EMFILE) for everyone, also for the controller's own link.
//! The caps ([`Caps::from_limit`]) leave [`RESERVED_FILES`] descriptors for the rest of the
//! process; a connection beyond a cap is accepted and closed at once (HTTP: after a JSON 503),
//! so the kernel's queue never fills with clients that wait for nothing. An accept that fails
//! anyway is logged once per interval ([`crate::ratelog`]) and retried after a back-off.

use std::fmt;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::str::FromStr;
use std::time::Duration;

use tokio::net::{TcpListener, TcpStream};

use super::ratelog;

/// Descriptors kept for the rest of the process (the controller link, stdio, the runtime).
pub const RESERVED_FILES: u64 = 64;
/// The longest back-off after a failed accept.
pub(crate) const MAX_ACCEPT_BACKOFF: Duration = Duration::from_secs(1);

/// The process's soft open-file limit, read at start (1024 if it cannot be read).
pub fn open_file_limit() -> u64 {
    nix::sys::resource::getrlimit(nix::sys::resource::Resource::RLIMIT_NOFILE)
        .map_or(1024, |(soft, _)| soft)
}

/// How many connections each front end holds at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Caps {
    /// HTTP connections served normally.
    pub http: usize,
    /// HTTP connections beyond [`Caps::http`] served with a short header timeout and no
    /// keep-alive (so a flood of idle sockets does not lock people out).
    pub http_overflow: usize,
    /// Modbus connections (never more than `--modbus-clients`).
    pub modbus: usize,
}

impl Caps {
    /// The caps for an open-file limit of `limit` and `modbus_clients`: the descriptors left
    /// after [`RESERVED_FILES`] go to HTTP (7/8, of which 1/8 overflow) and Modbus (1/8).
    pub fn from_limit(limit: u64, modbus_clients: usize) -> Caps {
        let usable = usize::try_from(limit.saturating_sub(RESERVED_FILES).min(1 << 20))
            .unwrap_or(1 << 20)
            .max(16);
        let modbus = modbus_clients.min(usable / 8).max(1);
        let http_total = usable - usable / 8;
        let http_overflow = (http_total / 8).max(1);
        Caps { http: http_total - http_overflow, http_overflow, modbus }
    }
}

/// Accepts the next connection; a failure (EMFILE, ECONNABORTED) is logged once per interval
/// and retried after a growing back-off, never returned: the server goes on.
pub async fn accept(listener: &TcpListener, name: &'static str) -> (TcpStream, SocketAddr) {
    let mut backoff = Duration::from_millis(5);
    loop {
        match listener.accept().await {
            Ok(accepted) => return accepted,
            Err(e) => {
                ratelog::global().log(
                    name,
                    "accept",
                    &format!(
                        "{name}: accepting a connection failed ({e}); retrying in {backoff:?}, \
                         the server goes on"
                    ),
                );
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(MAX_ACCEPT_BACKOFF);
            }
        }
    }
}

/// A network in CIDR notation (`192.168.10.0/24`, `10.0.0.7`, `::1/128`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cidr {
    network: IpAddr,
    prefix: u8,
}

/// Why a CIDR did not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "'{given}' is not a network: give ADDRESS/PREFIX such as 192.168.10.0/24 or an address \
     such as 192.168.10.7 ({why})"
)]
pub struct CidrError {
    given: String,
    why: &'static str,
}

impl FromStr for Cidr {
    type Err = CidrError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let error = |why| CidrError { given: s.to_owned(), why };
        let (address, prefix) = s.split_once('/').map_or((s, None), |(a, p)| (a, Some(p)));
        let network: IpAddr = address.parse().map_err(|_| error("the address does not parse"))?;
        let bits = if network.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => bits,
            Some(p) => p.parse::<u8>().map_err(|_| error("the prefix is not a number"))?,
        };
        if prefix > bits {
            return Err(error("the prefix is longer than the address"));
        }
        Ok(Cidr { network, prefix })
    }
}

impl fmt::Display for Cidr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.network, self.prefix)
    }
}

impl Cidr {
    /// Whether `ip` is in the network (an IPv4-mapped IPv6 address counts as its IPv4 one).
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        match (self.network, ip) {
            (IpAddr::V4(net), IpAddr::V4(ip)) => {
                let mask = u32::MAX.checked_shl(32 - u32::from(self.prefix)).unwrap_or(0);
                u32::from(net) & mask == u32::from(ip) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(ip)) => {
                let mask = u128::MAX.checked_shl(128 - u32::from(self.prefix)).unwrap_or(0);
                u128::from(net) & mask == u128::from(ip) & mask
            }
            _ => false,
        }
    }

    /// The loopback networks, the default allow-list.
    pub fn loopback() -> Vec<Cidr> {
        vec![
            Cidr { network: IpAddr::V4(Ipv4Addr::new(127, 0, 0, 0)), prefix: 8 },
            Cidr { network: IpAddr::V6(Ipv6Addr::LOCALHOST), prefix: 128 },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn networks_parse_and_contain_their_addresses() {
        let net: Cidr = "192.168.10.0/24".parse().unwrap();
        assert!(net.contains("192.168.10.77".parse().unwrap()));
        assert!(!net.contains("192.168.11.1".parse().unwrap()));
        assert!(net.contains("::ffff:192.168.10.3".parse().unwrap()));
        let host: Cidr = "10.0.0.7".parse().unwrap();
        assert!(host.contains("10.0.0.7".parse().unwrap()));
        assert!(!host.contains("10.0.0.8".parse().unwrap()));
        let all: Cidr = "0.0.0.0/0".parse().unwrap();
        assert!(all.contains("8.8.8.8".parse().unwrap()));
        assert!(Cidr::loopback().iter().any(|c| c.contains("127.3.4.5".parse().unwrap())));
        assert!(Cidr::loopback().iter().any(|c| c.contains("::1".parse().unwrap())));
        for bad in ["10.0.0.0/33", "plc", "10.0.0.0/x", "::/129"] {
            let e = bad.parse::<Cidr>().unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains("192.168.10.0/24"), "{e}");
        }
    }

    #[test]
    fn the_caps_stay_below_the_open_file_limit() {
        let caps = Caps::from_limit(1024, 1);
        assert_eq!(caps.modbus, 1);
        assert!(caps.http + caps.http_overflow + caps.modbus + 64 <= 1024, "{caps:?}");
        assert!(caps.http >= 500, "{caps:?}");
        let tiny = Caps::from_limit(10, 5);
        assert!(tiny.http >= 1 && tiny.modbus >= 1, "{tiny:?}");
        assert!(Caps::from_limit(u64::MAX, 3).modbus == 3);
    }
}
