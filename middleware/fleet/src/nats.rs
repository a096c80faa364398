//! The clustered engine: NATS with JetStream, for fleets that outgrow one broker.
//!
//! The cars keep speaking MQTT: every NATS node takes MQTT connections, maps a topic's
//! `/` to a subject's `.` (`autoplug/v1/vehicles/VIN/report/trip` is
//! `autoplug.v1.vehicles.VIN.report.trip`), keeps persistent sessions and retained
//! messages in JetStream, replicated by RAFT across the nodes, and checks each login's
//! rights per subject ([`crate::broker`] writes them: a car publishes only its reports,
//! reads only its commands, its receipts and the images).
//!
//! The fleet services do not share an MQTT subscription here: a stream
//! ([`STREAM`], work-queue retention, replicated on up to three nodes) keeps every report
//! the cars publish, and the services pull batches from one durable consumer
//! ([`CONSUMER`]): each report goes to one service at a time, stays in the stream until a
//! service acknowledges it (after its commit), and goes to another service when the one
//! holding it has not acknowledged it within [`ACK_WAIT`] (killed, cut off). A service only
//! holds what it asked for, one batch while it stores it: one that stops cleanly holds
//! nothing. Receipts, instructions and images go out over the service's MQTT connection,
//! as with Mosquitto, so an offline car finds them in its session.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use async_nats::jetstream::{self, consumer, stream, AckKind};
use futures_util::StreamExt;
use tokio::runtime::Handle;

use crate::mqtt::{parse_address_list, Ack, Message};

/// NATS's standard client port.
pub const DEFAULT_PORT: u16 = 4222;

/// The stream that keeps the cars' reports until a service stored them.
pub const STREAM: &str = "AUTOPLUG_REPORTS";

/// The subjects it keeps: every vehicle's reports.
pub const REPORT_SUBJECTS: &str = "autoplug.v1.vehicles.*.report.*";

/// The fleet services' durable consumer (one work queue they share).
pub const CONSUMER: &str = "autoplug-fleet";

/// How long a report handed to a service waits for its acknowledgement before the stream
/// hands it to another: the bound on how late a report held by a killed service arrives.
/// A service storing a batch for longer (a database failing) says it is still at it.
pub const ACK_WAIT: Duration = Duration::from_secs(10);

/// Reports held by the services together, unacknowledged, at most (each holds one batch).
pub const MAX_ACK_PENDING: i64 = 10_000;

/// The stream's size limit: past it a car's publish is refused (the car keeps the report
/// and sends it again: its outbox) rather than an older report dropped.
pub const MAX_STREAM_BYTES: i64 = 1 << 30;

/// The longest wait for the server's answer to a request (a pull, the stream's set-up).
const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

const NOT_CONNECTED: &str = "not connected to a node";

/// Connecting at start is not news for the operator until it lasts this long.
const QUIET_START: Duration = Duration::from_secs(5);

/// The subject of an MQTT topic (NATS's own mapping: `/` becomes `.`).
pub fn subject_of(topic: &str) -> String {
    topic.replace('/', ".")
}

/// The MQTT topic of a subject.
pub fn topic_of(subject: &str) -> String {
    subject.replace('.', "/")
}

/// NATS servers and the login: `nats://[USER[:PASSWORD]@]HOST[:PORT][,HOST[:PORT]…]` (a
/// cluster's nodes; the client moves to another when its node goes away).
#[derive(Clone, PartialEq, Eq)]
pub struct NatsServers {
    /// Host names or addresses with their client ports.
    pub addresses: Vec<(String, u16)>,
    /// The login.
    pub username: Option<String>,
    /// Its password.
    pub password: Option<String>,
}

impl std::fmt::Debug for NatsServers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NatsServers({self})")
    }
}

impl std::fmt::Display for NatsServers {
    /// The addresses without the password.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        crate::mqtt::display_address(f, "nats", &self.addresses, self.username.as_deref())
    }
}

impl std::str::FromStr for NatsServers {
    type Err = String;

    fn from_str(url: &str) -> Result<Self, String> {
        let (addresses, username, password) =
            parse_address_list(url, "nats", DEFAULT_PORT, "nats://127.0.0.1:4222")
                .map_err(|e| format!("work queue {e}"))?;
        Ok(Self {
            addresses,
            username,
            password,
        })
    }
}

/// What the work queue is doing, for the caller to show.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct QueueStatus {
    /// Connected to a node now.
    pub connected: bool,
    /// The stream and the consumer are there (made or found).
    pub ready: bool,
    /// The stream's replicas.
    pub replicas: usize,
    /// The last error, if any.
    pub last_error: Option<String>,
}

/// A fleet service's end of the work queue (see the module docs).
pub struct WorkQueue {
    runtime: Handle,
    client: async_nats::Client,
    consumer: Option<consumer::Consumer<consumer::pull::Config>>,
    status: Arc<Mutex<QueueStatus>>,
    servers: String,
    /// Notices the operator has not been told yet, oldest first: a queue, so that "the
    /// work queue is ready" is not overwritten by an error of the next pull before it is
    /// printed (seen: a CI run whose test waited for the ready line in vain).
    unseen: std::collections::VecDeque<String>,
    started: std::time::Instant,
}

/// Notices kept for the operator at most; older ones give way (each differs from the one
/// before, so this is a burst of distinct errors).
const MAX_NOTICES: usize = 16;

impl WorkQueue {
    /// Starts connecting to `servers` on `runtime` (returns at once; the stream and the
    /// consumer are made, if missing, at the first pull). `name` names the connection in
    /// the servers' monitoring.
    pub fn connect(runtime: &Handle, servers: &NatsServers, name: &str) -> Result<Self, String> {
        let mut options = match (&servers.username, &servers.password) {
            (Some(user), password) => async_nats::ConnectOptions::with_user_and_password(
                user.clone(),
                password.clone().unwrap_or_default(),
            ),
            (None, _) => async_nats::ConnectOptions::new(),
        };
        options = options
            .name(name)
            .retry_on_initial_connect()
            .max_reconnects(None)
            .connection_timeout(REQUEST_TIMEOUT)
            .request_timeout(Some(REQUEST_TIMEOUT))
            .ping_interval(Duration::from_secs(5))
            // Reconnect quickly to another node, at most every 2 s to one that is down.
            .reconnect_delay_callback(|attempts| {
                Duration::from_millis((100 * attempts as u64).min(2_000))
            });
        let addresses: Vec<async_nats::ServerAddr> = servers
            .addresses
            .iter()
            .map(|(host, port)| {
                format!("nats://{host}:{port}")
                    .parse::<async_nats::ServerAddr>()
                    .map_err(|e| format!("{servers}: {e}"))
            })
            .collect::<Result<_, _>>()?;
        let client = runtime
            .block_on(options.connect(addresses))
            .map_err(|e| format!("{servers}: {e}"))?;
        Ok(Self {
            runtime: runtime.clone(),
            client,
            consumer: None,
            status: Arc::new(Mutex::new(QueueStatus::default())),
            servers: servers.to_string(),
            unseen: std::collections::VecDeque::new(),
            started: std::time::Instant::now(),
        })
    }

    /// The servers, without the password.
    pub fn servers(&self) -> &str {
        &self.servers
    }

    /// What it is doing.
    pub fn status(&self) -> QueueStatus {
        let mut status = self.status.lock().map(|s| s.clone()).unwrap_or_default();
        status.connected =
            self.client.connection_state() == async_nats::connection::State::Connected;
        status
    }

    fn set_error(&mut self, error: String) {
        if error == NOT_CONNECTED && self.started.elapsed() < QUIET_START {
            return;
        }
        let new = match self.status.lock() {
            Ok(mut s) => {
                let new = s.last_error.as_ref() != Some(&error);
                s.last_error = Some(error.clone());
                new
            }
            Err(_) => false,
        };
        if new {
            self.notice(error);
        }
    }

    fn notice(&mut self, text: String) {
        if self.unseen.len() == MAX_NOTICES {
            self.unseen.pop_front();
        }
        self.unseen.push_back(text);
    }

    /// What the operator has not been told yet, oldest first: the queue ready, or a new
    /// error (one notice per error, not one per pull).
    pub fn take_notice(&mut self) -> Option<String> {
        self.unseen.pop_front()
    }

    /// The stream and the consumer, made if missing: the stream replicated on as many
    /// nodes as the cluster has, up to three (RAFT needs a majority: three survive one
    /// node lost).
    async fn set_up(
        client: async_nats::Client,
    ) -> Result<(consumer::Consumer<consumer::pull::Config>, usize), String> {
        if client.connection_state() != async_nats::connection::State::Connected {
            return Err(NOT_CONNECTED.into());
        }
        let info = client.server_info();
        let replicas = if info.cluster.is_some() {
            info.connect_urls.len().clamp(1, 3)
        } else {
            1
        };
        let js = jetstream::new(client);
        let config = stream::Config {
            name: STREAM.to_string(),
            description: Some(
                "AutoPlug: the vehicles' reports until a fleet service stored them".into(),
            ),
            subjects: vec![REPORT_SUBJECTS.to_string()],
            retention: stream::RetentionPolicy::WorkQueue,
            storage: stream::StorageType::File,
            num_replicas: replicas,
            max_bytes: MAX_STREAM_BYTES,
            discard: stream::DiscardPolicy::New,
            ..Default::default()
        };
        let stream = js
            .get_or_create_stream(config)
            .await
            .map_err(|e| format!("cannot make or find the stream {STREAM}: {e}"))?;
        let consumer = stream
            .get_or_create_consumer(
                CONSUMER,
                consumer::pull::Config {
                    durable_name: Some(CONSUMER.to_string()),
                    description: Some("AutoPlug fleet services (a shared work queue)".into()),
                    ack_policy: consumer::AckPolicy::Explicit,
                    ack_wait: ACK_WAIT,
                    max_deliver: -1,
                    max_ack_pending: MAX_ACK_PENDING,
                    ..Default::default()
                },
            )
            .await
            .map_err(|e| format!("cannot make or find the consumer {CONSUMER}: {e}"))?;
        let replicas = stream.cached_info().config.num_replicas.max(1);
        Ok((consumer, replicas))
    }

    /// Makes or finds the stream and the consumer, once.
    fn try_set_up(&mut self) -> Result<(), String> {
        if self.consumer.is_some() {
            return Ok(());
        }
        let client = self.client.clone();
        let outcome = self.runtime.block_on(async move {
            tokio::time::timeout(REQUEST_TIMEOUT * 2, Self::set_up(client)).await
        });
        match outcome {
            Ok(Ok((consumer, replicas))) => {
                self.consumer = Some(consumer);
                if let Ok(mut s) = self.status.lock() {
                    s.ready = true;
                    s.replicas = replicas;
                    s.last_error = None;
                }
                self.notice(format!(
                    "the work queue is ready: stream {STREAM} on {replicas} node(s), consumer {CONSUMER}"
                ));
                Ok(())
            }
            Ok(Err(e)) => {
                self.set_error(e.clone());
                Err(e)
            }
            Err(_) => {
                let e = format!("{}: no answer while setting up the stream", self.servers);
                self.set_error(e.clone());
                Err(e)
            }
        }
    }

    /// Waits until the stream and the consumer are there, at most `timeout`: reports the
    /// cars publish before the stream exists are kept by no one (the cars send them again
    /// when no receipt comes).
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<(), String> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            match self.try_set_up() {
                Ok(()) => return Ok(()),
                Err(e) if std::time::Instant::now() >= deadline => {
                    return Err(format!(
                        "{}: the work queue is not ready: {e}",
                        self.servers
                    ))
                }
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    /// The reports waiting now, at most `max`, waiting at most `wait` for the first: a
    /// pull of one that waits, then one of the rest that does not. Nothing is asked for
    /// that this call does not take, so the service holds only what it returns.
    pub fn recv_batch(&mut self, wait: Duration, max: usize) -> Vec<Message> {
        if self.consumer.is_none() && self.try_set_up().is_err() {
            std::thread::sleep(wait);
            return Vec::new();
        }
        let Some(consumer) = &self.consumer else {
            return Vec::new();
        };
        // The server wants a pull's expiry of 1 ms at least; one that waits for the first
        // report ends when it came or when `wait` is over.
        let wait = wait.max(Duration::from_millis(10));
        let first = self
            .runtime
            .block_on(answered_within(wait + PULL_GRACE, async {
                let batch = consumer
                    .batch()
                    .max_messages(1)
                    .expires(wait)
                    .messages()
                    .await;
                collect(batch).await
            }));
        let mut messages = match first {
            Ok(messages) => messages,
            Err(e) => {
                self.set_error(e);
                std::thread::sleep(wait);
                return Vec::new();
            }
        };
        if messages.is_empty() || max <= 1 {
            return messages;
        }
        let rest = self.runtime.block_on(answered_within(PULL_GRACE, async {
            let batch = consumer.fetch().max_messages(max - 1).messages().await;
            collect(batch).await
        }));
        match rest {
            Ok(more) => messages.extend(more),
            // What the first pull took is returned; the rest stays in the stream.
            Err(e) => self.set_error(e),
        }
        messages
    }

    /// Publishes `payload` to an MQTT `topic` through NATS itself: the cars connected now
    /// get it (at QoS 0), no stream keeps it. For receipts: a car that misses one sends its
    /// report again and gets the receipt of the duplicate. Never waits for the server.
    pub fn publish_now(&self, topic: &str, payload: Vec<u8>) -> Result<(), String> {
        let client = self.client.clone();
        let subject = subject_of(topic);
        self.runtime
            .block_on(async move { client.publish(subject, payload.into()).await })
            .map_err(|e| format!("cannot publish to {topic}: {e}"))
    }

    /// Acknowledges a message (its report stored or refused for good): the stream forgets it.
    pub fn ack(&self, message: &Message) -> Result<(), String> {
        self.reply(message, AckKind::Ack)
    }

    /// Says the service is still at `message` (a database that fails): the stream waits
    /// another [`ACK_WAIT`] before handing it to another service.
    pub fn in_progress(&self, message: &Message) -> Result<(), String> {
        self.reply(message, AckKind::Progress)
    }

    fn reply(&self, message: &Message, kind: AckKind) -> Result<(), String> {
        let Ack::JetStream(delivery) = &message.ack else {
            return Err("an MQTT message is acknowledged on its link".into());
        };
        self.runtime
            .block_on(async {
                tokio::time::timeout(REQUEST_TIMEOUT, delivery.ack_with(kind)).await
            })
            .map_err(|_| "the acknowledgement waited too long".to_string())?
            .map_err(|e| format!("cannot acknowledge: {e}"))
    }

    /// Sends what is buffered (the acknowledgements) and waits for the server to have
    /// taken it, at most `timeout`.
    pub fn flush(&self, timeout: Duration) {
        let _ = self
            .runtime
            .block_on(async { tokio::time::timeout(timeout, self.client.flush()).await });
    }
}

/// The deliveries of one pull, as messages; a pull that ends with an error keeps the
/// deliveries before it.
/// How long past its expiry a pull may go unanswered before it is given up. The server
/// ends a pull at its expiry; a pull in flight when its node went away is never ended (the
/// client reconnects elsewhere, the request is lost), and the service would wait on it
/// for ever (seen: a cluster test hung with a node killed mid-stream).
const PULL_GRACE: Duration = Duration::from_secs(5);

/// `pull`'s result, or an error once `limit` has passed without one.
async fn answered_within(
    limit: Duration,
    pull: impl std::future::Future<Output = Result<Vec<Message>, String>>,
) -> Result<Vec<Message>, String> {
    tokio::time::timeout(limit, pull).await.unwrap_or_else(|_| {
        Err(format!(
            "a pull of reports got no answer in {} s (its server gone?): pulling again",
            limit.as_secs_f64()
        ))
    })
}

async fn collect<S, E1, E2>(batch: Result<S, E1>) -> Result<Vec<Message>, String>
where
    S: futures_util::Stream<Item = Result<jetstream::Message, E2>> + Unpin,
    E1: std::fmt::Display,
    E2: std::fmt::Display,
{
    let mut batch = batch.map_err(|e| format!("cannot pull reports: {e}"))?;
    let mut messages = Vec::new();
    while let Some(delivery) = batch.next().await {
        match delivery {
            Ok(delivery) => messages.push(Message {
                topic: topic_of(delivery.subject.as_str()),
                payload: delivery.payload.to_vec(),
                retained: false,
                ack: Ack::JetStream(Box::new(delivery)),
            }),
            Err(e) if messages.is_empty() => return Err(format!("cannot pull reports: {e}")),
            Err(_) => break,
        }
    }
    Ok(messages)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subjects_and_topics_map_as_the_server_maps_them() {
        let topic = "autoplug/v1/vehicles/JA3AP47H0YF000042/report/trip";
        assert_eq!(
            subject_of(topic),
            "autoplug.v1.vehicles.JA3AP47H0YF000042.report.trip"
        );
        assert_eq!(topic_of(&subject_of(topic)), topic);
    }

    #[test]
    fn server_lists_parse_and_hide_the_password() {
        let s: NatsServers = "nats://autoplug-fleet:pw@127.0.0.1:4222,127.0.0.1:4223,host"
            .parse()
            .unwrap();
        assert_eq!(s.addresses.len(), 3);
        assert_eq!(s.addresses[2], ("host".to_string(), DEFAULT_PORT));
        assert_eq!(
            s.to_string(),
            "nats://autoplug-fleet@127.0.0.1:4222,127.0.0.1:4223,host:4222"
        );
        let e = "mqtt://u:pw@host".parse::<NatsServers>().unwrap_err();
        assert!(e.contains("nats://") && !e.contains("pw@"), "{e}");
    }
}
