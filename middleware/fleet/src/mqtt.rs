//! One MQTT connection, for code that is not async: a vehicle's gateway (the pipeline's
//! thread) or a fleet service's loop. The connection's event loop runs as a task on a
//! tokio runtime the caller shares between connections (a simulated fleet holds a thousand
//! of them); what arrives waits in a bounded queue, and publishing never blocks: a full
//! request queue is an error the caller sees.
//!
//! rumqttc does the protocol (MQTT 3.1.1, QoS 1, persistent sessions, keep-alive); this
//! adds what both sides of the fleet need around it: reconnecting with a backoff, the
//! subscriptions made again when the broker kept no session, a refused login or
//! subscription reported instead of retried blindly, and the state for the caller to show.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rumqttc::{
    AsyncClient, ConnectReturnCode, ConnectionError, Event, MqttOptions, Packet, Publish, QoS,
    SubscribeFilter, SubscribeReasonCode,
};
use tokio::runtime::Handle;
use tokio::sync::mpsc;

/// A runtime for MQTT connections, to share between them (two workers: the connections
/// only move bytes).
pub fn runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("mqtt")
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the MQTT runtime: {e}"))
}

/// The first wait before a refused subscription is asked for again (then doubling up to
/// the link's longest backoff).
pub const RESUBSCRIBE_WAIT: Duration = Duration::from_secs(2);

/// The broker's standard port for MQTT without TLS.
pub const DEFAULT_PORT: u16 = 1883;

/// The default broker: Mosquitto on this machine.
pub const DEFAULT_BROKER: &str = "mqtt://127.0.0.1:1883";

/// Largest message either side sends or takes, bytes: a signed image (the ECUs' slot is
/// 112 KiB) with room to spare. Mosquitto's own limit is larger by default.
pub const MAX_PACKET_BYTES: usize = 512 * 1024;

/// Messages that may wait for the caller before the connection stops reading (the broker
/// then holds the rest: nothing is lost, QoS 1 is acknowledged only once queued).
pub const INCOMING_CAPACITY: usize = 256;

/// Requests (publish, subscribe, acknowledge) that may wait for the connection.
pub const REQUEST_CAPACITY: usize = 256;

/// The longest [`MqttLink::ack`] and [`MqttLink::publish_waiting`] wait for room in the
/// request queue.
pub const REQUEST_WAIT: Duration = Duration::from_secs(5);

/// A broker's addresses and the login to use:
/// `mqtt://[USER[:PASSWORD]@]HOST[:PORT][,HOST[:PORT]…]`. Several addresses are the nodes
/// of one clustered broker: the connection takes the first and moves to the next each
/// time a connection fails, so a car whose node went away comes back through another.
#[derive(Clone, PartialEq, Eq)]
pub struct Broker {
    /// Host names or addresses with their TCP ports, in the order tried (at least one).
    pub addresses: Vec<(String, u16)>,
    /// The login, if the broker wants one.
    pub username: Option<String>,
    /// Its password.
    pub password: Option<String>,
}

impl Broker {
    /// One broker at `host:port`.
    pub fn at(host: impl Into<String>, port: u16) -> Self {
        Self {
            addresses: vec![(host.into(), port)],
            username: None,
            password: None,
        }
    }

    /// The same with a login.
    pub fn with_login(mut self, user: impl Into<String>, password: impl Into<String>) -> Self {
        self.username = Some(user.into());
        self.password = Some(password.into());
        self
    }
}

impl std::fmt::Debug for Broker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Broker({self})")
    }
}

/// `SCHEME://[USER@]HOST:PORT[,HOST:PORT…]`, without the password.
pub(crate) fn display_address(
    f: &mut std::fmt::Formatter<'_>,
    scheme: &str,
    addresses: &[(String, u16)],
    username: Option<&str>,
) -> std::fmt::Result {
    write!(f, "{scheme}://")?;
    if let Some(user) = username {
        write!(f, "{user}@")?;
    }
    for (i, (host, port)) in addresses.iter().enumerate() {
        if i > 0 {
            f.write_str(",")?;
        }
        write!(f, "{host}:{port}")?;
    }
    Ok(())
}

impl std::fmt::Display for Broker {
    /// The addresses without the password.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        display_address(f, "mqtt", &self.addresses, self.username.as_deref())
    }
}

/// The parts of `SCHEME://[USER[:PASSWORD]@]HOST[:PORT][,HOST[:PORT]…]`: the addresses
/// (`default_port` where none is given), the user and the password; an error naming what
/// is wrong, with the password hidden.
pub(crate) type AddressList = (Vec<(String, u16)>, Option<String>, Option<String>);

pub(crate) fn parse_address_list(
    url: &str,
    scheme: &str,
    default_port: u16,
    example: &str,
) -> Result<AddressList, String> {
    let rest = url
        .strip_prefix(scheme)
        .and_then(|r| r.strip_prefix("://"))
        .ok_or_else(|| {
            format!(
                "address '{}' must start with {scheme}:// (e.g. {example})",
                redact(url)
            )
        })?;
    let (login, hosts) = match rest.rsplit_once('@') {
        Some((login, hosts)) => (Some(login), hosts),
        None => (None, rest),
    };
    let (username, password) = match login {
        None => (None, None),
        Some(login) => match login.split_once(':') {
            Some((user, password)) => (Some(user.to_string()), Some(password.to_string())),
            None => (Some(login.to_string()), None),
        },
    };
    if username.as_deref() == Some("") {
        return Err(format!("address '{}' has an empty user name", redact(url)));
    }
    let mut addresses = Vec::new();
    for hostport in hosts.trim_end_matches('/').split(',') {
        let (host, port) = match hostport.rsplit_once(':') {
            Some((host, port)) => (
                host,
                port.parse::<u16>()
                    .ok()
                    .filter(|p| *p != 0)
                    .ok_or_else(|| format!("address '{}': '{port}' is not a port", redact(url)))?,
            ),
            None => (hostport, default_port),
        };
        if host.is_empty() || host.contains(['/', ' ', '@']) {
            return Err(format!("address '{}' names no host", redact(url)));
        }
        addresses.push((host.to_string(), port));
    }
    Ok((addresses, username, password))
}

impl std::str::FromStr for Broker {
    type Err = String;

    fn from_str(url: &str) -> Result<Self, String> {
        let (addresses, username, password) =
            parse_address_list(url, "mqtt", DEFAULT_PORT, DEFAULT_BROKER)
                .map_err(|e| format!("broker {e}"))?;
        Ok(Broker {
            addresses,
            username,
            password,
        })
    }
}

/// A URL with any password replaced, for error messages.
fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(scheme), Some(at)) if at > scheme => {
            let login = &url[scheme + 3..at];
            match login.split_once(':') {
                Some((user, _)) => format!("{}{user}:***{}", &url[..scheme + 3], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url.to_string(),
    }
}

/// How a connection is set up.
#[derive(Clone, Debug)]
pub struct LinkOptions {
    /// The MQTT client id (a vehicle: its VIN; the broker's ACL may require it to be the
    /// user name).
    pub client_id: String,
    /// Keep the session while disconnected: subscriptions stay, QoS 1 messages for the
    /// client are queued by the broker until it comes back.
    pub persistent_session: bool,
    /// Topics to subscribe to (QoS 1), again after every connect.
    pub subscriptions: Vec<String>,
    /// Acknowledge what arrives only when the caller says so ([`MqttLink::ack`]): a
    /// message is then taken from the broker only once it is handled (stored).
    pub manual_acks: bool,
    /// Keep-alive interval.
    pub keep_alive: Duration,
    /// First wait before reconnecting; doubled after each failure up to `max_backoff`.
    pub backoff: Duration,
    /// Longest wait before reconnecting.
    pub max_backoff: Duration,
}

impl LinkOptions {
    /// A client with the defaults: clean session, no subscriptions, automatic acks.
    pub fn new(client_id: impl Into<String>) -> Self {
        Self {
            client_id: client_id.into(),
            persistent_session: false,
            subscriptions: Vec::new(),
            manual_acks: false,
            keep_alive: Duration::from_secs(30),
            backoff: Duration::from_millis(250),
            max_backoff: Duration::from_secs(30),
        }
    }
}

/// A vehicle's MQTT client id: its VIN, and with a password a tag made from it
/// (`VIN-` and 16 hex digits of SHA-256 over the password and the VIN). A car that knows
/// another's VIN cannot work out its client id without its password, so it cannot take
/// over the other's session, also on a broker that does not bind client ids to logins
/// (NATS); Mosquitto's plugin binds each login to its own (`broker add`). Without a
/// password (a broker that takes anyone, on one machine) the VIN alone.
pub fn vehicle_client_id(vin: &str, password: Option<&str>) -> String {
    use sha2::Digest;
    match password.filter(|p| !p.is_empty()) {
        Some(password) => {
            let mut hash = sha2::Sha256::new();
            hash.update(b"autoplug mqtt client id\0");
            hash.update(password.as_bytes());
            hash.update(b"\0");
            hash.update(vin.as_bytes());
            let tag: String = hash.finalize()[..8]
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            format!("{vin}-{tag}")
        }
        None => vin.to_string(),
    }
}

/// The keep-alive of a fleet service's connection: a service whose machine stops
/// answering is out of the shared group 1.5 times this after its last packet (the broker's
/// rule), and the reports it held go to the others with the cars' resends.
pub const SERVICE_KEEP_ALIVE: Duration = Duration::from_secs(5);

/// How a fleet service connects: a session that ends with the connection, manual
/// acknowledgements, [`SERVICE_KEEP_ALIVE`]. A service's session must not outlive it: in a
/// shared subscription Mosquitto hands a kept session of a stopped service its turn of
/// every report, and those wait there until a process with its client id comes back (its
/// issue 1747). Ended with the connection, the session takes the reports it held
/// unacknowledged with it, and the cars publish those again (their outbox): a report is
/// never stranded.
pub fn service_options(client_id: impl Into<String>) -> LinkOptions {
    let mut options = LinkOptions::new(client_id);
    options.persistent_session = false;
    options.manual_acks = true;
    options.keep_alive = SERVICE_KEEP_ALIVE;
    options
}

/// A message that arrived.
#[derive(Clone, Debug)]
pub struct Message {
    /// Its topic.
    pub topic: String,
    /// Its payload.
    pub payload: Vec<u8>,
    /// Whether the broker delivered it as a retained message.
    pub retained: bool,
    /// How it is acknowledged, and to whom.
    pub(crate) ack: Ack,
}

/// What acknowledges a message: its MQTT PUBLISH (to the link that took it), or a
/// JetStream delivery of the clustered engine's work queue ([`crate::nats::WorkQueue`]).
#[derive(Clone, Debug)]
pub(crate) enum Ack {
    Mqtt(Publish),
    JetStream(Box<async_nats::jetstream::Message>),
}

impl Message {
    /// A message that needs no acknowledgement (tests, a message made up).
    pub fn unacknowledged(topic: &str, payload: &[u8]) -> Self {
        Message {
            topic: topic.to_string(),
            payload: payload.to_vec(),
            retained: false,
            ack: Ack::Mqtt(Publish::new(topic, QoS::AtMostOnce, payload.to_vec())),
        }
    }
}

/// What the connection is doing, for the caller to show.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LinkStatus {
    /// Connected to the broker now.
    pub connected: bool,
    /// Connections made (the first and every reconnect).
    pub connects: u64,
    /// The broker refused the login (wrong user or password, not authorized): the
    /// connection keeps trying at its longest backoff, since credentials may be fixed.
    pub refused: Option<String>,
    /// The last error of the connection, if any.
    pub last_error: Option<String>,
    /// Subscriptions the broker refuses (its ACL; a clustered broker that could not set
    /// one up in time), by topic: asked for again after [`RESUBSCRIBE_WAIT`], doubling.
    pub denied: Vec<String>,
    /// Subscriptions the broker granted since the last connect.
    pub granted: Vec<String>,
    /// Publishes the broker acknowledged (PUBACK): it took them, which is not yet stored.
    pub acknowledged: u64,
    /// Which of the broker's addresses it uses (or tries) now, from 0.
    pub address: usize,
}

/// Why a request could not be made.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinkError(pub String);

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LinkError {}

/// One connection to the broker (see the module docs). Dropping it disconnects.
pub struct MqttLink {
    client: AsyncClient,
    incoming: mpsc::Receiver<Message>,
    status: Arc<Mutex<LinkStatus>>,
    runtime: Handle,
    task: tokio::task::JoinHandle<()>,
    broker: String,
    subscribing: Subscribing,
}

/// The topics of each SUBSCRIBE not yet answered, in the order sent (a broker answers in
/// that order), so each SUBACK's codes name their topics.
type Subscribing = Arc<Mutex<std::collections::VecDeque<Vec<String>>>>;

impl MqttLink {
    /// Starts connecting to `broker` on `runtime` (returns at once: see [`Self::status`]
    /// and [`Self::wait_connected`]).
    pub fn connect(runtime: &Handle, broker: &Broker, options: LinkOptions) -> Self {
        let mqtt = mqtt_options(broker, 0, &options);
        let (client, mut eventloop) = AsyncClient::new(mqtt, REQUEST_CAPACITY);
        // Small messages sent at once: with Nagle's algorithm a receipt or an
        // acknowledgement waited for the peer's delayed ACK (tens of ms on loopback).
        let mut network = eventloop.network_options();
        network.set_tcp_nodelay(true);
        eventloop.set_network_options(network);
        let (tx, incoming) = mpsc::channel(INCOMING_CAPACITY);
        let status = Arc::new(Mutex::new(LinkStatus::default()));
        let subscribing = Subscribing::default();
        let task = runtime.spawn(run(
            eventloop,
            broker.clone(),
            tx,
            status.clone(),
            subscribing.clone(),
            options,
            client.clone(),
        ));
        Self {
            subscribing,
            client,
            incoming,
            status,
            runtime: runtime.clone(),
            task,
            broker: broker.to_string(),
        }
    }

    /// Whether the broker granted `topic` on this connection (a car sends its reports
    /// only once its receipts can reach it: a clustered broker may take a while, or
    /// refuse for a while, to set a subscription up, and a receipt sent meanwhile is lost,
    /// which costs the report a resend much later).
    pub fn subscribed(&self, topic: &str) -> bool {
        self.status
            .lock()
            .is_ok_and(|s| s.connected && s.granted.iter().any(|t| t == topic))
    }

    /// The broker, without the password.
    pub fn broker(&self) -> &str {
        &self.broker
    }

    /// What the connection is doing.
    pub fn status(&self) -> LinkStatus {
        self.status.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// Waits until connected with every subscription answered, at most `timeout`; the
    /// refusal or the last error if not.
    pub fn wait_connected(&self, timeout: Duration) -> Result<(), LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            let status = self.status();
            if let Some(refused) = status.refused {
                return Err(LinkError(format!("{}: {refused}", self.broker)));
            }
            if status.connected {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(LinkError(format!(
                    "{}: not connected after {:.1} s{}",
                    self.broker,
                    timeout.as_secs_f64(),
                    status
                        .last_error
                        .map_or(String::new(), |e| format!(" ({e})"))
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Publishes at QoS 1 (at least once); `retain` keeps it at the broker for later
    /// subscribers. Never blocks: an error when the request queue is full.
    pub fn publish(&self, topic: &str, payload: Vec<u8>, retain: bool) -> Result<(), LinkError> {
        if payload.len() > MAX_PACKET_BYTES - topic.len() - 16 {
            return Err(LinkError(format!(
                "a message of {} bytes is larger than the {MAX_PACKET_BYTES} bytes allowed",
                payload.len()
            )));
        }
        self.client
            .try_publish(topic, QoS::AtLeastOnce, retain, payload)
            .map_err(|e| LinkError(format!("cannot publish to {topic}: {e}")))
    }

    /// Subscribes (QoS 1) to one more topic, now; not made again after a reconnect.
    pub fn subscribe(&self, topic: &str) -> Result<(), LinkError> {
        if let Ok(mut pending) = self.subscribing.lock() {
            pending.push_back(vec![topic.to_string()]);
        }
        self.client
            .try_subscribe(topic, QoS::AtLeastOnce)
            .map_err(|e| LinkError(format!("cannot subscribe to {topic}: {e}")))
    }

    /// Ends a subscription made with [`Self::subscribe`].
    pub fn unsubscribe(&self, topic: &str) -> Result<(), LinkError> {
        self.client
            .try_unsubscribe(topic)
            .map_err(|e| LinkError(format!("cannot unsubscribe from {topic}: {e}")))
    }

    /// The next message, if one waits.
    pub fn try_recv(&mut self) -> Option<Message> {
        self.incoming.try_recv().ok()
    }

    /// The next message, waiting at most `timeout` (from a thread outside the runtime).
    pub fn recv_timeout(&mut self, timeout: Duration) -> Option<Message> {
        let incoming = &mut self.incoming;
        self.runtime
            .block_on(async { tokio::time::timeout(timeout, incoming.recv()).await })
            .ok()
            .flatten()
    }

    /// Acknowledges a message (with manual acks): the broker may forget it. Waits for room
    /// in the request queue (at most [`REQUEST_WAIT`]): an acknowledgement dropped for a
    /// full queue would hold one of the broker's in-flight slots for the connection's
    /// life, and a few dozen of them stop its deliveries. While disconnected there is
    /// nothing to acknowledge: the broker delivers the message again on the next
    /// connection (the session is kept).
    pub fn ack(&self, message: &Message) -> Result<(), LinkError> {
        match &message.ack {
            Ack::Mqtt(publish) => self.send_waiting("acknowledge", self.client.ack(publish)),
            Ack::JetStream(_) => Err(LinkError(
                "a message of the work queue is acknowledged there".into(),
            )),
        }
    }

    /// Publishes at QoS 1 like [`Self::publish`], but waits (at most [`REQUEST_WAIT`]) for
    /// room in the request queue instead of failing at once; fails at once while
    /// disconnected.
    pub fn publish_waiting(
        &self,
        topic: &str,
        payload: Vec<u8>,
        retain: bool,
    ) -> Result<(), LinkError> {
        if payload.len() > MAX_PACKET_BYTES - topic.len() - 16 {
            return Err(LinkError(format!(
                "a message of {} bytes is larger than the {MAX_PACKET_BYTES} bytes allowed",
                payload.len()
            )));
        }
        self.send_waiting(
            "publish",
            self.client
                .publish(topic, QoS::AtLeastOnce, retain, payload),
        )
    }

    fn send_waiting(
        &self,
        what: &str,
        request: impl std::future::Future<Output = Result<(), rumqttc::ClientError>>,
    ) -> Result<(), LinkError> {
        if !self.status().connected {
            return Err(LinkError(format!("cannot {what}: not connected")));
        }
        match self
            .runtime
            .block_on(async { tokio::time::timeout(REQUEST_WAIT, request).await })
        {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(LinkError(format!("cannot {what}: {e}"))),
            Err(_) => Err(LinkError(format!(
                "cannot {what}: the request queue stayed full for {} s",
                REQUEST_WAIT.as_secs()
            ))),
        }
    }

    /// Disconnects cleanly (the broker keeps a persistent session), waiting at most
    /// `timeout` for what was published to be sent.
    pub fn close(self, timeout: Duration) {
        let _ = self.client.try_disconnect();
        let deadline = Instant::now() + timeout;
        while !self.task.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for MqttLink {
    fn drop(&mut self) {
        let _ = self.client.try_disconnect();
        self.task.abort();
    }
}

/// The connection's settings for `broker`'s address number `address`.
fn mqtt_options(broker: &Broker, address: usize, options: &LinkOptions) -> MqttOptions {
    let (host, port) = broker
        .addresses
        .get(address)
        .or(broker.addresses.first())
        .cloned()
        .unwrap_or_else(|| ("127.0.0.1".to_string(), DEFAULT_PORT));
    let mut mqtt = MqttOptions::new(options.client_id.clone(), host, port);
    mqtt.set_keep_alive(options.keep_alive)
        .set_clean_session(!options.persistent_session)
        .set_max_packet_size(MAX_PACKET_BYTES, MAX_PACKET_BYTES)
        .set_request_channel_capacity(REQUEST_CAPACITY)
        .set_manual_acks(options.manual_acks);
    if let Some(user) = &broker.username {
        mqtt.set_credentials(user.clone(), broker.password.clone().unwrap_or_default());
    }
    mqtt
}

fn set(status: &Mutex<LinkStatus>, change: impl FnOnce(&mut LinkStatus)) {
    if let Ok(mut s) = status.lock() {
        change(&mut s);
    }
}

/// The connection's event loop: reconnects with a backoff, subscribes after every connect,
/// hands publishes to the caller.
async fn run(
    mut eventloop: rumqttc::EventLoop,
    broker: Broker,
    tx: mpsc::Sender<Message>,
    status: Arc<Mutex<LinkStatus>>,
    subscribing: Subscribing,
    options: LinkOptions,
    client: AsyncClient,
) {
    let mut backoff = options.backoff;
    // Subscriptions refused, each with the wait before it is asked for again: a clustered
    // broker refuses one it could not set up in time (NATS: its JetStream consumer), and
    // rights fixed at the broker take effect without a reconnect.
    let mut refused_waits: std::collections::HashMap<String, Duration> =
        std::collections::HashMap::new();
    let mut address = 0;
    // With manual acks, messages the caller's queue had no room for wait here rather than
    // stop the event loop: a caller acknowledging (or publishing a receipt) waits for the
    // event loop to take its request, and an event loop waiting for the caller to take a
    // message never would (the keep-alive then expired and the service took nothing more).
    // The broker sends a client at most its in-flight window of unacknowledged messages
    // (Mosquitto: 20), which bounds what waits; every acknowledgement wakes this loop to
    // hand the next over.
    let mut held: std::collections::VecDeque<Message> = std::collections::VecDeque::new();
    loop {
        while let Some(message) = held.pop_front() {
            match tx.try_send(message) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(message)) => {
                    held.push_front(message);
                    break;
                }
                Err(mpsc::error::TrySendError::Closed(_)) => return,
            }
        }
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                backoff = options.backoff;
                set(&status, |s| {
                    s.connected = true;
                    s.connects += 1;
                    s.refused = None;
                    s.granted.clear();
                });
                // SUBSCRIBEs of the lost connection will not be answered.
                if let Ok(mut pending) = subscribing.lock() {
                    pending.clear();
                }
                // Subscribe on every connection, kept session or not: Mosquitto 2.0 keeps a
                // persistent session across its restart but not the session's shared
                // (`$share/…`) subscriptions, so a service that trusted `session_present`
                // stayed connected and subscribed to nothing. Subscribing again to what a
                // session holds changes nothing else.
                //
                // The SUBSCRIBE goes first, ahead of the request queue: while the broker was
                // away that queue filled (a service's acknowledgements and receipts), and a
                // SUBSCRIBE refused for a full queue left the service subscribed to nothing
                // (20 cars through a broker restart: ingest stopped for good).
                if !options.subscriptions.is_empty() {
                    if let Ok(mut pending) = subscribing.lock() {
                        pending.push_back(options.subscriptions.clone());
                    }
                    let filters = options
                        .subscriptions
                        .iter()
                        .map(|t| SubscribeFilter::new(t.clone(), QoS::AtLeastOnce));
                    eventloop.pending.push_front(rumqttc::Request::Subscribe(
                        rumqttc::Subscribe::new_many(filters),
                    ));
                }
            }
            Ok(Event::Incoming(Packet::SubAck(ack))) => {
                let topics = subscribing
                    .lock()
                    .ok()
                    .and_then(|mut p| p.pop_front())
                    .unwrap_or_default();
                let mut again = Vec::new();
                set(&status, |s| {
                    for (i, code) in ack.return_codes.iter().enumerate() {
                        let topic = topics.get(i).cloned().unwrap_or_else(|| format!("#{i}"));
                        match code {
                            SubscribeReasonCode::Success(_) => {
                                s.denied.retain(|t| *t != topic);
                                refused_waits.remove(&topic);
                                s.granted.push(topic);
                            }
                            SubscribeReasonCode::Failure => {
                                if !s.denied.contains(&topic) {
                                    s.denied.push(topic.clone());
                                }
                                again.push(topic);
                            }
                        }
                    }
                });
                for topic in again {
                    let wait = refused_waits.get(&topic).map_or(RESUBSCRIBE_WAIT, |w| {
                        (*w * 2).min(options.max_backoff.max(RESUBSCRIBE_WAIT))
                    });
                    refused_waits.insert(topic.clone(), wait);
                    let (client, subscribing) = (client.clone(), subscribing.clone());
                    tokio::spawn(async move {
                        tokio::time::sleep(wait).await;
                        if let Ok(mut pending) = subscribing.lock() {
                            pending.push_back(vec![topic.clone()]);
                        }
                        let _ = client.subscribe(topic, QoS::AtLeastOnce).await;
                    });
                }
            }
            Ok(Event::Incoming(Packet::Publish(publish))) => {
                let message = Message {
                    topic: publish.topic.clone(),
                    payload: publish.payload.to_vec(),
                    retained: publish.retain,
                    ack: Ack::Mqtt(publish),
                };
                if options.manual_acks {
                    if held.is_empty() {
                        match tx.try_send(message) {
                            Ok(()) => {}
                            Err(mpsc::error::TrySendError::Full(message)) => {
                                held.push_back(message)
                            }
                            Err(mpsc::error::TrySendError::Closed(_)) => return,
                        }
                    } else {
                        held.push_back(message);
                    }
                } else if tx.send(message).await.is_err() {
                    return; // The link was dropped.
                }
            }
            Ok(Event::Incoming(Packet::PubAck(_))) => set(&status, |s| s.acknowledged += 1),
            Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => {
                set(&status, |s| s.connected = false);
                // Let the DISCONNECT go out, then stop.
                let _ = tokio::time::timeout(Duration::from_millis(200), eventloop.poll()).await;
                return;
            }
            Ok(_) => {}
            Err(error) => {
                let refused = match &error {
                    ConnectionError::ConnectionRefused(
                        code @ (ConnectReturnCode::BadUserNamePassword
                        | ConnectReturnCode::NotAuthorized
                        | ConnectReturnCode::BadClientId),
                    ) => Some(format!("the broker refused the login ({code:?})")),
                    _ => None,
                };
                let wait = if refused.is_some() {
                    options.max_backoff
                } else {
                    backoff
                };
                set(&status, |s| {
                    s.connected = false;
                    s.last_error = Some(error.to_string());
                    if refused.is_some() {
                        s.refused = refused;
                    }
                });
                if matches!(error, ConnectionError::RequestsDone) {
                    return;
                }
                tokio::time::sleep(wait).await;
                backoff = (backoff * 2).min(options.max_backoff);
                // The next node of a clustered broker (each address tried in turn).
                if broker.addresses.len() > 1 {
                    address = (address + 1) % broker.addresses.len();
                    eventloop.mqtt_options = mqtt_options(&broker, address, &options);
                    set(&status, |s| s.address = address);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vehicles_client_id_is_its_vin_and_a_tag_only_its_password_makes() {
        let vin = "JA3AP47H0YF000042";
        let id = vehicle_client_id(vin, Some("s3cret"));
        assert_eq!(id.len(), 17 + 1 + 16);
        assert!(id.starts_with("JA3AP47H0YF000042-"), "{id}");
        assert_eq!(id, vehicle_client_id(vin, Some("s3cret")));
        assert_ne!(id, vehicle_client_id(vin, Some("s3cret2")));
        assert_ne!(
            id[18..],
            vehicle_client_id("JA3AP47H2YF000043", Some("s3cret"))[18..]
        );
        assert_eq!(vehicle_client_id(vin, None), vin);
        assert_eq!(vehicle_client_id(vin, Some("")), vin);
    }

    #[test]
    fn broker_addresses_parse_and_hide_the_password() {
        let b: Broker = "mqtt://127.0.0.1:1883".parse().unwrap();
        assert_eq!(
            (b.addresses.clone(), b.username.clone()),
            (vec![("127.0.0.1".to_string(), 1883)], None)
        );
        let b: Broker = "mqtt://JA3AP47H0YF000042:s3cret@broker.example:8883"
            .parse()
            .unwrap();
        assert_eq!(b.username.as_deref(), Some("JA3AP47H0YF000042"));
        assert_eq!(b.password.as_deref(), Some("s3cret"));
        assert_eq!(
            b.to_string(),
            "mqtt://JA3AP47H0YF000042@broker.example:8883"
        );
        assert_eq!(
            "mqtt://host".parse::<Broker>().unwrap().addresses,
            [("host".to_string(), 1883)]
        );
        // A clustered broker's nodes, tried in turn.
        let b: Broker = "mqtt://car:pw@10.0.0.1,10.0.0.2:1884,node3:1885"
            .parse()
            .unwrap();
        assert_eq!(
            b.addresses,
            [
                ("10.0.0.1".to_string(), 1883),
                ("10.0.0.2".to_string(), 1884),
                ("node3".to_string(), 1885)
            ]
        );
        assert_eq!(
            b.to_string(),
            "mqtt://car@10.0.0.1:1883,10.0.0.2:1884,node3:1885"
        );
        assert!("mqtt://h1,,h2"
            .parse::<Broker>()
            .unwrap_err()
            .contains("names no host"));
        let e = "tcp://u:pw@host".parse::<Broker>().unwrap_err();
        assert!(
            e.contains("mqtt://") && e.contains("u:***@host") && !e.contains("pw"),
            "{e}"
        );
        let e = "mqtt://u:pw@host:99999".parse::<Broker>().unwrap_err();
        assert!(e.contains("not a port") && !e.contains("pw@"), "{e}");
        assert!("mqtt://:pw@host".parse::<Broker>().is_err());
        assert!("mqtt://".parse::<Broker>().is_err());
    }
}
