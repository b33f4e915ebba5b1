//! Rate-limited log lines on stderr: at most one line per client and cause per
//! [`LOG_INTERVAL`], the next one saying how many were held back. A client that sends a
//! thousand bad frames a second costs a line every few seconds, not megabytes.
//!
//! The table of (client, cause) is bounded ([`MAX_KEYS`]): when full, entries whose interval
//! is over are dropped, and if none is, new clients share one `*` entry per cause.

use std::collections::HashMap;
use std::io::Write as _;
use std::sync::{Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// The shortest gap between two lines of one client and cause.
pub const LOG_INTERVAL: Duration = Duration::from_secs(5);
/// The most (client, cause) pairs tracked at once.
pub const MAX_KEYS: usize = 1024;

#[derive(Debug)]
struct Entry {
    since: Instant,
    held: u64,
}

/// A rate limiter of log lines, writing to a sink (stderr for [`global`]).
pub struct RateLog {
    entries: Mutex<HashMap<(String, &'static str), Entry>>,
    interval: Duration,
}

impl RateLog {
    /// A limiter with its own table and `interval`.
    pub fn new(interval: Duration) -> Self {
        RateLog { entries: Mutex::new(HashMap::new()), interval }
    }

    /// The line to print for `message` from `client` about `cause` now, if any: `None` while
    /// the pair's interval runs (the line is counted), else the message with the count held
    /// back since the last line.
    pub fn admit(&self, client: &str, cause: &'static str, message: &str) -> Option<String> {
        let now = Instant::now();
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        if entries.len() >= MAX_KEYS && !entries.contains_key(&(client.to_owned(), cause)) {
            entries.retain(|_, e| now.duration_since(e.since) < self.interval);
        }
        let key = if entries.len() >= MAX_KEYS { "*".to_owned() } else { client.to_owned() };
        match entries.get_mut(&(key.clone(), cause)) {
            Some(entry) if now.duration_since(entry.since) < self.interval => {
                entry.held += 1;
                None
            }
            Some(entry) => {
                let held = std::mem::take(&mut entry.held);
                entry.since = now;
                Some(if held == 0 {
                    message.to_owned()
                } else {
                    format!("{message} (and {held} more like it in the last {:?})", self.interval)
                })
            }
            None => {
                entries.insert((key, cause), Entry { since: now, held: 0 });
                Some(message.to_owned())
            }
        }
    }

    /// Prints `message` on stderr unless the pair's interval runs.
    pub fn log(&self, client: &str, cause: &'static str, message: &str) {
        if let Some(line) = self.admit(client, cause, message) {
            // A closed stderr must not end the server.
            let _ = writeln!(std::io::stderr().lock(), "{line}");
        }
    }
}

/// The process's limiter, with [`LOG_INTERVAL`].
pub fn global() -> &'static RateLog {
    static LOG: OnceLock<RateLog> = OnceLock::new();
    LOG.get_or_init(|| RateLog::new(LOG_INTERVAL))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_per_client_and_cause_per_interval_then_the_count() {
        let log = RateLog::new(Duration::from_millis(200));
        assert_eq!(log.admit("10.0.0.1", "bad", "x").as_deref(), Some("x"));
        for _ in 0..1000 {
            assert_eq!(log.admit("10.0.0.1", "bad", "x"), None);
        }
        // Another client or cause has its own interval.
        assert!(log.admit("10.0.0.2", "bad", "y").is_some());
        assert!(log.admit("10.0.0.1", "other", "z").is_some());
        let start = Instant::now();
        let line = loop {
            if let Some(line) = log.admit("10.0.0.1", "bad", "x") {
                break line;
            }
            assert!(start.elapsed() < Duration::from_secs(5), "the interval never ended");
            std::thread::yield_now();
        };
        let held: u64 = line["x (and ".len()..].split(' ').next().unwrap().parse().unwrap();
        assert!(held >= 1000, "{line}");
    }

    #[test]
    fn the_table_stays_bounded_with_many_clients() {
        let log = RateLog::new(Duration::from_secs(60));
        for i in 0..5000 {
            log.admit(&format!("client {i}"), "bad", "x");
        }
        let entries = log.entries.lock().unwrap();
        assert!(entries.len() <= MAX_KEYS + 1, "{}", entries.len());
    }
}
