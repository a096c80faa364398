//! The server's connections, built for clients that open them and say nothing.
//!
//! axum's own `serve` accepts for as long as the process has file descriptors and keeps a
//! silent connection for ever: about 1,100 idle connections took every descriptor of a
//! process with the usual limit of 1024, and from then on the page loaded for no one. Here:
//! - a connection has [`REQUEST_DEADLINE`] to send its first request and
//!   [`KEEP_ALIVE_LIMIT`] to send the next one (HTTP keep-alive), and its request headers
//!   must arrive within [`REQUEST_DEADLINE`] (slow headers);
//! - at most [`connection_limit`] connections at once, well below the descriptor limit;
//!   when a new one comes at the limit, the one that has waited longest without a request
//!   under way is closed for it, so idle connections can never lock a client out; only when
//!   every connection is busy is the new one refused, with a 503 (the room for that
//!   descriptor is in the limit).
//!
//! A connection upgraded to the stream leaves this count (the streams have their own limit,
//! `WebConfig::max_clients`, which the descriptor budget keeps room for).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::{TcpListener, TcpStream};
use tokio::task::AbortHandle;

/// How long a new connection may take to send its request's headers.
pub const REQUEST_DEADLINE: Duration = Duration::from_secs(5);
/// How long a connection may wait between two requests.
pub const KEEP_ALIVE_LIMIT: Duration = Duration::from_secs(30);
/// Most connections at once, whatever the descriptor limit.
pub const MAX_CONNECTIONS: usize = 4096;

/// How often the deadlines are checked.
const SWEEP_PERIOD: Duration = Duration::from_millis(500);

/// Connections at once for this process: half its descriptor limit (the rest for the
/// streams, the gateway's files and sockets, and the refusals), at most
/// [`MAX_CONNECTIONS`].
pub fn connection_limit() -> usize {
    descriptor_limit()
        .map_or(256, |limit| (limit / 2) as usize)
        .clamp(16, MAX_CONNECTIONS)
}

#[cfg(unix)]
fn descriptor_limit() -> Option<u64> {
    rlimit::getrlimit(rlimit::Resource::NOFILE)
        .ok()
        .map(|(soft, _)| soft)
}

#[cfg(not(unix))]
fn descriptor_limit() -> Option<u64> {
    None
}

/// A connection's place in the registry.
struct Entry {
    abort: AbortHandle,
    /// Since when it waits for a request; `None` while one is under way.
    waiting_since: Option<Instant>,
    /// Whether it has had a request yet.
    served: bool,
}

#[derive(Default)]
struct Registry {
    next: u64,
    open: BTreeMap<u64, Entry>,
}

#[derive(Clone, Default)]
struct Connections(Arc<Mutex<Registry>>);

impl Connections {
    fn lock(&self) -> MutexGuard<'_, Registry> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn count(&self) -> usize {
        self.lock().open.len()
    }

    /// Closes the connection that has waited longest for a request; `false` when every
    /// one has a request under way.
    fn evict_longest_waiting(&self) -> bool {
        let mut registry = self.lock();
        let oldest = registry
            .open
            .iter()
            .filter_map(|(&id, e)| e.waiting_since.map(|since| (since, id)))
            .min();
        match oldest.and_then(|(_, id)| registry.open.remove(&id)) {
            Some(entry) => {
                entry.abort.abort();
                true
            }
            None => false,
        }
    }

    /// Closes the connections past their deadlines at `now`.
    fn sweep(&self, now: Instant) {
        self.lock().open.retain(|_, e| {
            let limit = if e.served {
                KEEP_ALIVE_LIMIT
            } else {
                REQUEST_DEADLINE
            };
            let late = e
                .waiting_since
                .is_some_and(|since| now.duration_since(since) >= limit);
            if late {
                e.abort.abort();
            }
            !late
        });
    }

    fn set_waiting(&self, id: u64, waiting: bool) {
        if let Some(entry) = self.lock().open.get_mut(&id) {
            entry.waiting_since = waiting.then(Instant::now);
            entry.served = true;
        }
    }
}

/// Takes a connection off the registry however its task ends (done, failed, aborted).
struct Registered {
    connections: Connections,
    id: u64,
}

impl Drop for Registered {
    fn drop(&mut self) {
        self.connections.lock().open.remove(&self.id);
    }
}

/// Serves `app` on `listener` until the future is dropped, at most `limit` connections at
/// once.
pub async fn serve(listener: TcpListener, app: Router, limit: usize) {
    let connections = Connections::default();
    {
        // Ends with the runtime, as every connection's task does.
        let connections = connections.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(SWEEP_PERIOD);
            loop {
                tick.tick().await;
                connections.sweep(Instant::now());
            }
        });
    }
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            // Out of descriptors or a connection gone before it was taken: go on shortly
            // (the limit keeps the first from happening through this server).
            Err(_) => {
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        if connections.count() >= limit && !connections.evict_longest_waiting() {
            refuse(&stream);
            continue;
        }
        start(stream, app.clone(), &connections);
    }
}

/// Serves one connection on a task of its own, registered until it ends.
fn start(stream: TcpStream, app: Router, connections: &Connections) {
    let _ = stream.set_nodelay(true);
    let mut registry = connections.lock();
    let id = registry.next;
    registry.next += 1;
    let registered = Registered {
        connections: connections.clone(),
        id,
    };
    let marks = connections.clone();
    let service = tower::service_fn(move |request: hyper::Request<hyper::body::Incoming>| {
        let app = app.clone();
        let marks = marks.clone();
        async move {
            marks.set_waiting(id, false);
            let request = request.map(axum::body::Body::new);
            let response = tower::ServiceExt::oneshot(app, request).await;
            marks.set_waiting(id, true);
            response
        }
    });
    let task = tokio::spawn(async move {
        let _registered = registered;
        let _ = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(REQUEST_DEADLINE)
            .serve_connection(TokioIo::new(stream), TowerToHyperService::new(service))
            .with_upgrades()
            .await;
    });
    registry.open.insert(
        id,
        Entry {
            abort: task.abort_handle(),
            waiting_since: Some(Instant::now()),
            served: false,
        },
    );
}

/// Answers a connection the server has no room for and closes it: what the socket's
/// buffer takes at once (all of it, on a new connection), never a wait, so a flood of
/// refusals holds no descriptor.
fn refuse(stream: &TcpStream) {
    const BODY: &str = r#"{"error":"the server has as many connections as it takes: try again"}"#;
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{BODY}",
        BODY.len()
    );
    let _ = stream.try_write(answer.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_leaves_room_below_the_descriptor_limit() {
        let limit = connection_limit();
        assert!((16..=MAX_CONNECTIONS).contains(&limit));
        if let Some(descriptors) = descriptor_limit() {
            assert!((limit as u64) <= descriptors / 2 || limit == 16);
        }
    }
}
