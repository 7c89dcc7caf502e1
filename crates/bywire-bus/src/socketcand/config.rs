//! What a socketcand server allows (who, how much) and what it counts: shared by the server
//! and its sessions.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Who may use the server.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Access {
    /// Bus names clients may open (empty: any name).
    pub names: Vec<String>,
    /// When set, clients must send `< auth TOKEN >` before anything else (an extension of
    /// ours: plain socketcand clients cannot, so it is for listeners beyond this host). A
    /// wrong token closes the connection; attempts are paced to ten a second server-wide.
    pub token: Option<String>,
}

/// What the server allows each client and all of them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limits {
    /// Connections served at once; more are told so and closed.
    pub max_clients: usize,
    /// Cyclic (`add`) jobs per client.
    pub jobs_per_client: usize,
    /// Cyclic jobs over all clients.
    pub jobs_total: usize,
    /// The shortest interval of a cyclic job (0 stays allowed: it sends once).
    pub min_interval: Duration,
    /// Subscriptions and content filters per client.
    pub subscriptions_per_client: usize,
    /// A connection that has not opened a bus by then is closed.
    pub handshake_timeout: Duration,
    /// A client that accepts no data for this long is closed.
    pub write_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_clients: 64,
            jobs_per_client: 64,
            jobs_total: 1024,
            min_interval: Duration::from_millis(1),
            subscriptions_per_client: 2048,
            handshake_timeout: Duration::from_secs(10),
            write_timeout: Duration::from_secs(10),
        }
    }
}

/// A server's access rules and limits.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Config {
    /// Who may use it.
    pub access: Access,
    /// What it allows.
    pub limits: Limits,
}

/// Counts the server keeps over all clients.
#[derive(Debug, Default)]
pub struct ServerStats {
    /// Clients accepted.
    pub clients: AtomicU64,
    /// Clients served now.
    pub active: AtomicU64,
    /// Connections refused because the server was full (or could not start a thread).
    pub refused_clients: AtomicU64,
    /// Frames not delivered because a client's queue was full.
    pub dropped: AtomicU64,
    /// Frames a client's bus endpoint dropped because its forwarding fell behind.
    pub dropped_at_endpoint: AtomicU64,
    /// Malformed or refused commands answered with an error.
    pub errors: AtomicU64,
    /// Cyclic jobs refused by a limit.
    pub refused_jobs: AtomicU64,
    /// Wrong tokens and commands before the token.
    pub auth_failures: AtomicU64,
    /// Connections closed for not opening a bus in time.
    pub timed_out: AtomicU64,
    /// Connections closed because the client stopped reading.
    pub stalled: AtomicU64,
    /// Failed `accept` calls (such as "too many open files"); the server waits and goes on.
    pub accept_errors: AtomicU64,
}

/// A counter's value now.
pub(super) fn load(counter: &AtomicU64) -> u64 {
    counter.load(Ordering::Relaxed)
}

impl ServerStats {
    /// Frames the server lost for its clients (full queues and endpoints).
    pub fn dropped_total(&self) -> u64 {
        load(&self.dropped) + load(&self.dropped_at_endpoint)
    }

    /// One line for the end of a run.
    pub fn summary(&self) -> String {
        format!(
            "clients {} (refused {}, timed out {}, stalled {}), frames dropped for slow clients {} (queue {}, endpoint {}), malformed or refused commands {}, cyclic jobs refused {}, failed authentications {}, accept errors {}",
            load(&self.clients),
            load(&self.refused_clients),
            load(&self.timed_out),
            load(&self.stalled),
            self.dropped_total(),
            load(&self.dropped),
            load(&self.dropped_at_endpoint),
            load(&self.errors),
            load(&self.refused_jobs),
            load(&self.auth_failures),
            load(&self.accept_errors),
        )
    }
}
