//! The HTTP and WebSocket server, on a thread of its own with a single-threaded tokio
//! runtime: the gateway's pipeline only publishes into the [`LiveTable`] and never waits
//! for the network.
//!
//! Built for hostile clients: a request whose `Host` names neither the address the server
//! listens on nor a name the user allowed gets 421 before anything is read or sent (DNS
//! rebinding: a page the user visits points its own name at 127.0.0.1, and the browser
//! sends that name), at most [`WebConfig::max_clients`] streams at once (more get
//! 503), an `Origin` header that is not the server's own (or configured) gets 403, incoming
//! WebSocket messages are limited to [`MAX_INCOMING_BYTES`], a client that does not take an
//! update within [`SEND_TIMEOUT`] is dropped, and a slow one gets coalesced updates (see
//! [`crate::live`]). Every error is a JSON body `{"error": "..."}` that says what was wrong.

use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::Deserialize;
use tokio::sync::oneshot;

use crate::control::{Button, Command, Control, HeldControls, SendError};
use crate::live::LiveTable;

/// How often a client gets an update at most (20 Hz, the dashboard's rate).
pub const UPDATE_PERIOD: Duration = Duration::from_millis(50);
/// A client that does not take a message in this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(2);
/// Largest WebSocket message a client may send (commands are small).
pub const MAX_INCOMING_BYTES: usize = 4096;
/// Streams at once by default.
pub const DEFAULT_MAX_CLIENTS: usize = 64;
/// A stream passes the driver's controls to the session at most this often; what comes
/// meanwhile replaces what waits (the latest state wins), so one stream cannot fill the
/// queue the others' commands share.
pub const DRIVE_INTERVAL: Duration = Duration::from_millis(10);
/// Button presses a stream may make per second (each one is passed on, none coalesced).
pub const PRESSES_PER_SECOND: u32 = 20;

/// Where and for whom the server listens.
#[derive(Clone, Debug)]
pub struct WebConfig {
    /// The address: loopback unless the user says otherwise.
    pub addr: SocketAddr,
    /// Origins besides the server's own that may open the stream from a browser
    /// (`http://host:port`).
    pub allowed_origins: Vec<String>,
    /// Host names besides the listening address the server answers for (`name` or
    /// `name:port`; without a port, the server's): a name in a request's `Host` that is
    /// neither is refused.
    pub allowed_hosts: Vec<String>,
    /// Streams at once.
    pub max_clients: usize,
    /// Connections at once (see [`crate::connections`]): by default half the process's
    /// file descriptor limit.
    pub max_connections: usize,
    /// The token write actions need (`Authorization: Bearer TOKEN`, or the stream's
    /// `auth` message); `None`: the dashboard only shows, and every write is refused.
    pub token: Option<String>,
    /// The trip database the Trips view reads (SQLite), if any.
    pub trips_db: Option<PathBuf>,
    /// Where the recordings are, for their list and download.
    pub recordings_dir: Option<PathBuf>,
    /// The firmware library: signed images the ECUs view offers to flash.
    pub images_dir: Option<PathBuf>,
    /// The fleet's campaigns, for the Fleet view (`GET /api/fleet/...`), if this server
    /// shows them.
    pub fleet: Option<Arc<dyn crate::fleet::FleetData>>,
    /// Whether a bus stands behind the stream (`false`: a fleet page only, and the page
    /// shows only its Fleet view).
    pub live: bool,
}

impl WebConfig {
    /// Loopback on `port` (0: any free port).
    pub fn loopback(port: u16) -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], port)),
            allowed_origins: Vec::new(),
            allowed_hosts: Vec::new(),
            max_clients: DEFAULT_MAX_CLIENTS,
            max_connections: crate::connections::connection_limit(),
            token: None,
            trips_db: None,
            recordings_dir: None,
            images_dir: None,
            fleet: None,
            live: true,
        }
    }
}

pub(crate) struct Shared {
    pub(crate) table: Arc<LiveTable>,
    pub(crate) config: WebConfig,
    /// The address the server listens on (its port, when the configuration said 0).
    local: SocketAddr,
    clients: AtomicUsize,
    pub(crate) control: Option<Control>,
    /// One fleet query at a time.
    pub(crate) fleet_queries: Arc<tokio::sync::Semaphore>,
}

/// The running server; dropping it stops it.
pub struct WebServer {
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl WebServer {
    /// Binds `config.addr` (an error names the address) and serves `table` from a thread;
    /// write actions go to `control` (without one, the dashboard only shows).
    pub fn start(
        config: WebConfig,
        table: Arc<LiveTable>,
        control: Option<Control>,
    ) -> std::io::Result<Self> {
        let listener = TcpListener::bind(config.addr).map_err(|e| {
            std::io::Error::new(e.kind(), format!("cannot listen on {}: {e}", config.addr))
        })?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()?;
        let (stop, stopped) = oneshot::channel::<()>();
        let max_connections = config.max_connections;
        let shared = Arc::new(Shared {
            table,
            config,
            local: addr,
            clients: AtomicUsize::new(0),
            control,
            fleet_queries: Arc::new(tokio::sync::Semaphore::new(1)),
        });
        let thread = std::thread::Builder::new()
            .name("web server".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        return;
                    };
                    let app = router(shared);
                    // No graceful shutdown: it would wait for open streams, which end only
                    // when their client leaves. Leaving `block_on` drops the runtime, which
                    // cancels every connection's task and closes its socket.
                    tokio::select! {
                        _ = crate::connections::serve(listener, app, max_connections) => {}
                        _ = stopped => {}
                    }
                });
            })?;
        Ok(Self {
            addr,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for WebServer {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/api/catalog", get(catalog))
        .route("/api/state", get(state))
        .route("/api/world", get(world))
        .route("/api/stream", get(stream))
        .merge(crate::api::routes())
        .fallback(crate::assets::serve)
        .layer(axum::middleware::from_fn_with_state(
            shared.clone(),
            refuse_foreign_hosts,
        ))
        .with_state(shared)
}

/// Answers 421 to a request whose `Host` is not this server's (see [`host_allowed`]),
/// before any handler runs: the stream's upgrade included.
async fn refuse_foreign_hosts(
    State(shared): State<Arc<Shared>>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    // A request without `Host` is no browser's (HTTP/1.1 browsers always send it).
    if let Some(host) = request.headers().get(header::HOST) {
        let host = host.to_str().unwrap_or("");
        if !host_allowed(host, &shared.config, shared.local) {
            let shown = cut(host, 100);
            return error(
                StatusCode::MISDIRECTED_REQUEST,
                format!("this server does not answer for the host '{shown}' (start it with --allowed-host NAME to allow a name)"),
            );
        }
    }
    next.run(request).await
}

/// Whether a `Host` header names this server: an IP address it listens on (any of the
/// machine's when it listens on all of them: an address cannot be rebound), `localhost`
/// when it listens on loopback, or a name the user allowed; with the port it listens on
/// (none: 80).
pub fn host_allowed(host: &str, config: &WebConfig, local: SocketAddr) -> bool {
    let (name, port) = match host.strip_prefix('[') {
        Some(rest) => match rest.split_once(']') {
            Some((name, tail)) => (name, tail.strip_prefix(':')),
            None => return false,
        },
        None => match host.rsplit_once(':') {
            Some((name, port)) => (name, Some(port)),
            None => (host, None),
        },
    };
    let port = match port {
        Some(port) => match port.parse::<u16>() {
            Ok(port) => port,
            Err(_) => return false,
        },
        None => 80,
    };
    let name = name.to_ascii_lowercase();
    let allowed_name = config.allowed_hosts.iter().any(|allowed| {
        let allowed = allowed.to_ascii_lowercase();
        match allowed.rsplit_once(':') {
            Some((n, p)) if p.parse::<u16>().is_ok() => n == name && p.parse() == Ok(port),
            _ => allowed == name && port == local.port(),
        }
    });
    if allowed_name {
        return true;
    }
    if port != local.port() {
        return false;
    }
    let listening = local.ip();
    match name.parse::<std::net::IpAddr>() {
        Ok(ip) => {
            ip == listening
                || listening.is_unspecified()
                || (listening.is_loopback() && ip.is_loopback())
        }
        Err(_) => name == "localhost" && (listening.is_loopback() || listening.is_unspecified()),
    }
}

/// An error answer: the status and a JSON body naming what was wrong.
pub(crate) fn error(status: StatusCode, message: impl Into<String>) -> Response {
    (status, Json(serde_json::json!({ "error": message.into() }))).into_response()
}

/// The 404 of an unknown path.
pub(crate) fn not_found(uri: &Uri) -> Response {
    let path: String = uri.path().chars().take(200).collect();
    error(StatusCode::NOT_FOUND, format!("no such path: {path}"))
}

/// Whether `given` is the configured token: compared in time independent of where they
/// differ, so the answer's timing does not give the token away a byte at a time.
pub(crate) fn token_matches(config: &WebConfig, given: &str) -> bool {
    let Some(token) = config.token.as_deref() else {
        return false;
    };
    let (a, b) = (token.as_bytes(), given.as_bytes());
    let mut diff = a.len() ^ b.len();
    for (i, x) in a.iter().enumerate() {
        diff |= usize::from(x ^ b.get(i).copied().unwrap_or(!x));
    }
    diff == 0
}

async fn catalog() -> Response {
    Json(LiveTable::catalog_message()).into_response()
}

async fn state(State(shared): State<Arc<Shared>>) -> Response {
    let (json, _) = shared.table.update_since(0);
    ([(header::CONTENT_TYPE, "application/json")], json).into_response()
}

/// The world channel's whole content (the description and the poses kept), as the
/// stream's first `world` message; `{"type":"world","description":null,"poses":[]}` when
/// the bus has no world (a real bus).
async fn world(State(shared): State<Arc<Shared>>) -> Response {
    let body = shared
        .table
        .world()
        .message_since(crate::world::WorldCursor::default())
        .map_or_else(
            || r#"{"type":"world","description":null,"poses":[]}"#.to_string(),
            |(json, _)| json,
        );
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

/// Whether a browser's `Origin` may open the stream: the server's own host, or one the
/// user allowed. Tools that send no `Origin` (python, PlotJuggler) are not browsers
/// running someone else's page, and may.
fn origin_allowed(headers: &HeaderMap, config: &WebConfig) -> bool {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return true;
    };
    let Ok(origin) = origin.to_str() else {
        return false;
    };
    let own = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .is_some_and(|host| origin == format!("http://{host}"));
    own || config.allowed_origins.iter().any(|o| o == origin)
}

/// Counts a stream while it lives.
struct ClientSlot(Arc<Shared>);

impl Drop for ClientSlot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::SeqCst);
    }
}

async fn stream(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    upgrade: Result<WebSocketUpgrade, axum::extract::ws::rejection::WebSocketUpgradeRejection>,
) -> Response {
    if !origin_allowed(&headers, &shared.config) {
        return error(
            StatusCode::FORBIDDEN,
            "this origin may not open the stream (start the gateway with --web-origin to allow it)",
        );
    }
    let upgrade = match upgrade {
        Ok(upgrade) => upgrade,
        Err(rejection) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!("/api/stream is a WebSocket: {rejection}"),
            )
        }
    };
    let taken = shared.clients.fetch_add(1, Ordering::SeqCst);
    let slot = ClientSlot(shared.clone());
    if taken >= shared.config.max_clients {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{} streams already open", shared.config.max_clients),
        );
    }
    upgrade
        .max_message_size(MAX_INCOMING_BYTES)
        .max_frame_size(MAX_INCOMING_BYTES)
        .on_upgrade(move |socket| serve_stream(socket, slot))
}

/// What a client may send: `{"type":"ping"}`, `{"type":"auth","token":T}`,
/// `{"type":"drive", …the held controls…}`, `{"type":"press","button":B}`.
///
/// Parsed by its `type` first, then the rest as a plain struct, rather than as a serde
/// internally tagged enum: those buffer numbers through `deserialize_any`, which breaks
/// when a crate in the same build turns on serde_json's `arbitrary_precision`
/// (defmt-decoder does).
#[derive(Debug)]
enum ClientMessage {
    /// Answered with `{"type":"pong"}`.
    Ping,
    /// The write token: this stream may drive from now on (answered `auth`, `ok`).
    Auth { token: String },
    /// The person at the wheel (after `auth`).
    Drive(HeldControls),
    /// A steering-wheel button (after `auth`).
    Press { button: Button },
}

impl ClientMessage {
    fn parse(text: &str) -> Result<ClientMessage, serde_json::Error> {
        use serde::de::Error;
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Empty {}
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Auth {
            token: String,
        }
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Press {
            button: Button,
        }
        let mut fields = serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(text)?;
        let kind = match fields.remove("type") {
            Some(serde_json::Value::String(kind)) => kind,
            Some(_) => return Err(serde_json::Error::custom("`type` is not a string")),
            None => return Err(serde_json::Error::missing_field("type")),
        };
        let rest = serde_json::Value::Object(fields);
        Ok(match kind.as_str() {
            "ping" => {
                serde_json::from_value::<Empty>(rest)?;
                ClientMessage::Ping
            }
            "auth" => ClientMessage::Auth {
                token: serde_json::from_value::<Auth>(rest)?.token,
            },
            "drive" => {
                let held = serde_json::from_value::<HeldControls>(rest)?;
                // A number beyond f64 (1e999) reads as infinity: as malformed as a string.
                for (name, value) in [
                    ("accelerator", held.accelerator),
                    ("brake", held.brake),
                    ("steering_deg", held.steering_deg),
                    ("set_temp_f", held.set_temp_f),
                ] {
                    if !value.is_finite() {
                        return Err(serde_json::Error::custom(format!(
                            "`{name}` is {value}: not a finite number"
                        )));
                    }
                }
                ClientMessage::Drive(held)
            }
            "press" => ClientMessage::Press {
                button: serde_json::from_value::<Press>(rest)?.button,
            },
            other => {
                return Err(serde_json::Error::unknown_variant(
                    other,
                    &["ping", "auth", "drive", "press"],
                ))
            }
        })
    }
}

/// A stream's client, as far as driving goes.
#[derive(Default)]
struct Driver {
    authenticated: bool,
    drove: bool,
    /// Controls received and not passed on yet (the latest).
    pending: Option<HeldControls>,
    /// When controls were last passed on.
    last_drive: Option<tokio::time::Instant>,
    /// Presses in the current second, and when it began.
    presses: (u32, Option<tokio::time::Instant>),
}

impl Driver {
    /// What to answer to a client's message (`None`: nothing).
    fn on_message(&mut self, text: &str, shared: &Shared) -> Option<serde_json::Value> {
        let message = match ClientMessage::parse(text) {
            Ok(message) => message,
            Err(e) => {
                return Some(serde_json::json!({
                    "type": "error",
                    "error": format!("not a command: {}", cut(&e.to_string(), 200)),
                }))
            }
        };
        let command = match message {
            ClientMessage::Ping => return Some(serde_json::json!({ "type": "pong" })),
            ClientMessage::Auth { token } => {
                self.authenticated = token_matches(&shared.config, &token);
                return Some(serde_json::json!({ "type": "auth", "ok": self.authenticated }));
            }
            ClientMessage::Drive(_) | ClientMessage::Press { .. } if !self.authenticated => {
                return Some(serde_json::json!({
                    "type": "error",
                    "error": "driving needs the token: send {\"type\":\"auth\",\"token\":\"...\"} first",
                }))
            }
            ClientMessage::Drive(input) => {
                if shared.control.is_some() {
                    self.pending = Some(input);
                    return self.pass_drive(shared, tokio::time::Instant::now());
                }
                Command::Drive(input)
            }
            ClientMessage::Press { button } => {
                let now = tokio::time::Instant::now();
                let (count, since) = &mut self.presses;
                if since.is_none_or(|s| now.duration_since(s) >= Duration::from_secs(1)) {
                    *count = 0;
                    *since = Some(now);
                }
                *count += 1;
                if *count > PRESSES_PER_SECOND {
                    return Some(serde_json::json!({
                        "type": "error",
                        "error": format!("too many button presses: at most {PRESSES_PER_SECOND} a second"),
                    }));
                }
                Command::Press(button)
            }
        };
        let Some(control) = shared.control.as_ref() else {
            return Some(serde_json::json!({
                "type": "error",
                "error": "this gateway takes no commands (it only shows the bus)",
            }));
        };
        match control.send(command) {
            Ok(()) => {
                self.drove = true;
                None
            }
            Err(SendError::Busy) => Some(serde_json::json!({
                "type": "error", "error": "the session is busy: input dropped",
            })),
            Err(SendError::Gone) => Some(serde_json::json!({
                "type": "error", "error": "the session has ended",
            })),
        }
    }
}

impl Driver {
    /// When the controls waiting may be passed on, if any wait.
    fn drive_due(&self) -> Option<tokio::time::Instant> {
        self.pending?;
        Some(
            self.last_drive
                .map_or_else(tokio::time::Instant::now, |last| last + DRIVE_INTERVAL),
        )
    }

    /// Passes the waiting controls on if their interval has passed (or keeps them, the
    /// queue full, for the next try).
    fn pass_drive(
        &mut self,
        shared: &Shared,
        now: tokio::time::Instant,
    ) -> Option<serde_json::Value> {
        let input = self.pending?;
        if self
            .last_drive
            .is_some_and(|last| now < last + DRIVE_INTERVAL)
        {
            return None;
        }
        let control = shared.control.as_ref()?;
        self.last_drive = Some(now);
        match control.send(Command::Drive(input)) {
            Ok(()) => {
                self.pending = None;
                self.drove = true;
                None
            }
            // Tried again at the next interval, with whatever is latest by then.
            Err(SendError::Busy) => None,
            Err(SendError::Gone) => {
                self.pending = None;
                Some(serde_json::json!({ "type": "error", "error": "the session has ended" }))
            }
        }
    }
}

/// Releases the pedals when the stream of a client that drove ends, whatever ended it.
struct DriverGuard {
    driver: Driver,
    control: Option<Control>,
}

impl Drop for DriverGuard {
    fn drop(&mut self) {
        if let (true, Some(control)) = (self.driver.drove, self.control.as_ref()) {
            // The fast way; if the queue is full, the session's own dead-man timer
            // releases the pedals when the inputs stop coming.
            let _ = control.send(Command::DriverLeft);
        }
    }
}

async fn send(socket: &mut WebSocket, text: String) -> bool {
    matches!(
        tokio::time::timeout(SEND_TIMEOUT, socket.send(Message::Text(text.into()))).await,
        Ok(Ok(()))
    )
}

async fn serve_stream(mut socket: WebSocket, slot: ClientSlot) {
    let table = slot.0.table.clone();
    // Subscribed before the first snapshot: a change published while it is taken or sent
    // still wakes this client (subscribing later would mark it seen, and lose it).
    let mut changes = table.subscribe();
    let catalog = LiveTable::catalog_message();
    if !send(&mut socket, catalog.to_string()).await {
        return;
    }
    let (first, mut version) = table.update_since(0);
    if !send(&mut socket, first).await {
        return;
    }
    let mut driver = DriverGuard {
        driver: Driver::default(),
        control: slot.0.control.clone(),
    };
    let driver = &mut driver.driver;
    let mut ticker = tokio::time::interval(UPDATE_PERIOD);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // A change not sent yet: it goes at the next tick, at most one update per period.
    // Messages are read as they come meanwhile (waiting for the tick inside the loop held
    // them up to a period each, and a driver's inputs queued up behind it).
    let mut changed_since = false;
    // The world channel has no waker: it is looked at on a ticker of its own, and sent
    // when its version moved (the simulator publishes at 20 Hz).
    let world = table.world().clone();
    let mut world_cursor = crate::world::WorldCursor::default();
    let mut world_seen = u64::MAX;
    let mut world_ticker = tokio::time::interval(UPDATE_PERIOD);
    world_ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let drive_due = driver.drive_due();
        tokio::select! {
            _ = world_ticker.tick() => {
                let version = world.version();
                if version != world_seen {
                    world_seen = version;
                    if let Some((message, cursor)) = world.message_since(world_cursor) {
                        world_cursor = cursor;
                        if !send(&mut socket, message).await {
                            return;
                        }
                    }
                }
            }
            changed = changes.changed(), if !changed_since => {
                if changed.is_err() {
                    return; // the table is gone: the gateway stopped
                }
                changed_since = true;
            }
            _ = ticker.tick(), if changed_since => {
                changed_since = false;
                let (update, now) = table.update_since(version);
                if now > version {
                    if !send(&mut socket, update).await {
                        return;
                    }
                    version = now;
                }
            }
            _ = tokio::time::sleep_until(drive_due.unwrap_or_else(tokio::time::Instant::now)), if drive_due.is_some() => {
                if let Some(reply) = driver.pass_drive(&slot.0, tokio::time::Instant::now()) {
                    if !send(&mut socket, reply.to_string()).await {
                        return;
                    }
                }
            }
            incoming = socket.recv() => {
                let reply = match incoming {
                    None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return,
                    Some(Ok(Message::Text(text))) => match driver.on_message(&text, &slot.0) {
                        Some(reply) => reply,
                        None => continue,
                    },
                    Some(Ok(Message::Binary(_))) => serde_json::json!({
                        "type": "error",
                        "error": "binary messages are not understood: send JSON text",
                    }),
                    Some(Ok(_)) => continue, // ping and pong: the library answers
                };
                if !send(&mut socket, reply.to_string()).await {
                    return;
                }
            }
        }
    }
}

pub(crate) fn cut(text: &str, max: usize) -> String {
    text.chars().take(max).collect()
}

#[cfg(test)]
mod client_message_tests {
    use super::ClientMessage;

    #[test]
    fn client_messages_parse_by_type_and_refuse_what_does_not_fit() {
        assert!(matches!(
            ClientMessage::parse(r#"{"type":"ping"}"#),
            Ok(ClientMessage::Ping)
        ));
        assert!(
            matches!(ClientMessage::parse(r#"{"type":"auth","token":"t"}"#), Ok(ClientMessage::Auth { token }) if token == "t")
        );
        assert!(ClientMessage::parse(r#"{"type":"ping","extra":1}"#).is_err());
        assert!(ClientMessage::parse(r#"{"type":"fly"}"#)
            .unwrap_err()
            .to_string()
            .contains("unknown variant `fly`"));
        assert!(ClientMessage::parse(r#"{"token":"t"}"#)
            .unwrap_err()
            .to_string()
            .contains("missing field `type`"));
        assert!(ClientMessage::parse("[1]").is_err());
    }

    #[test]
    fn a_drive_message_with_a_number_beyond_f64_is_refused() {
        let drive = |accelerator: &str| {
            format!(
                r#"{{"type":"drive","accelerator":{accelerator},"brake":0,"steering_deg":0,"headlights":false,"economy_mode":true,"manual_mode":false,"set_temp_f":70}}"#
            )
        };
        assert!(matches!(
            ClientMessage::parse(&drive("12.5")),
            Ok(ClientMessage::Drive(held)) if held.accelerator == 12.5
        ));
        // Refused whether serde_json reads it as out of range or (with `arbitrary_precision`,
        // on in the workspace's build) as infinity.
        for number in ["1e999", "-1e999"] {
            let error = ClientMessage::parse(&drive(number))
                .unwrap_err()
                .to_string();
            assert!(
                error.contains("`accelerator`") || error.contains("out of range"),
                "{number}: {error}"
            );
        }
    }
}
