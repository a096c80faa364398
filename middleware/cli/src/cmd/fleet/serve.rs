//! `autoplug fleet serve`: the fleet service, the vehicles' reports from the broker into
//! the database and the campaigns' instructions out, with the fleet page if asked.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::ingest::Ingest;
use autoplug_fleet::ingest::DRAIN_QUIET;
use autoplug_fleet::mqtt::{LinkOptions, MqttLink};
use autoplug_fleet::nats::{NatsServers, WorkQueue};
use autoplug_fleet::service::FleetService;
use autoplug_fleet::topics;
use autoplug_image::SigningKey;

use super::{io, mqtt_runtime, open};
use crate::fleet_cli::{BrokerArgs, DbArgs, ServeArgs};

/// Checks the service's MQTT settings and runs it.
pub(crate) fn run(args: ServeArgs, out: &mut dyn Write) -> Result<(), String> {
    let ServeArgs {
        db,
        broker,
        key,
        tick,
        duration,
        client_id,
        group,
        persistent_session,
        clean_session: _,
        queue,
        queue_password_file,
        web,
        allowed_hosts,
    } = args;
    let mut options = autoplug_fleet::mqtt::service_options(client_id);
    options.persistent_session = persistent_session;
    if group.is_empty() || group.contains(['/', '+', '#']) {
        return Err(format!("'{group}' cannot name a group (no '/', '+', '#')"));
    }
    let queue = match queue {
        Some(mut servers) => {
            if let Some(path) = &queue_password_file {
                let password = std::fs::read_to_string(path)
                    .map_err(|e| format!("cannot read '{}': {e}", path.display()))?;
                servers.password = Some(password.trim_end_matches(['\r', '\n']).to_string());
            }
            Some(servers)
        }
        // The reports through the broker, split by a shared subscription.
        None => {
            options.subscriptions = vec![topics::reports_shared(&group)];
            None
        }
    };
    let settings = ServeSettings {
        key,
        tick,
        duration,
        web,
        allowed_hosts,
        queue,
    };
    serve(&db, &broker, settings, options, out)
}

/// `autoplug fleet serve`'s settings besides the database and the broker.
struct ServeSettings {
    key: Option<PathBuf>,
    tick: f64,
    duration: Option<f64>,
    web: Option<std::net::SocketAddr>,
    allowed_hosts: Vec<String>,
    queue: Option<NatsServers>,
}

/// Runs the service (and the fleet page) until Ctrl-C or `--duration`, then prints what
/// it stored and sent.
fn serve(
    db: &DbArgs,
    broker: &BrokerArgs,
    settings: ServeSettings,
    options: LinkOptions,
    out: &mut dyn Write,
) -> Result<(), String> {
    let ServeSettings {
        key,
        tick,
        duration,
        web,
        allowed_hosts,
        queue,
    } = settings;
    if !(tick.is_finite() && (0.01..=3600.0).contains(&tick)) {
        return Err("--tick is 0.01 to 3600 seconds".into());
    }
    let key = key.as_deref().map(read_key).transpose()?;
    let store = open(db)?;
    // The fleet page reads through a connection of its own (the service's is busy).
    let _page_server = match web {
        Some(addr) => {
            let page = autoplug_dashboard::fleet_page::FleetPage::open(&db.db)?;
            let config = autoplug_web::WebConfig {
                addr,
                fleet: Some(Arc::new(page)),
                live: false,
                allowed_hosts,
                ..autoplug_web::WebConfig::loopback(0)
            };
            let server = autoplug_web::WebServer::start(
                config,
                Arc::new(autoplug_web::LiveTable::new()),
                None,
            )
            .map_err(|e| e.to_string())?;
            writeln!(out, "fleet page on http://{}/fleet", server.addr()).map_err(io)?;
            Some(server)
        }
        None => None,
    };
    let runtime = mqtt_runtime()?;
    let broker = broker.broker()?;
    let subscription = options.subscriptions.first().cloned().unwrap_or_default();
    let name = options.client_id.clone();
    let link = MqttLink::connect(runtime.handle(), &broker, options);
    link.wait_connected(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    let queue = match queue {
        Some(servers) => {
            let mut queue = WorkQueue::connect(runtime.handle(), &servers, &name)?;
            queue.wait_ready(Duration::from_secs(10))?;
            Some(queue)
        }
        None => None,
    };
    let source = match &queue {
        Some(queue) => format!(
            "the work queue at {} (receipts through {broker})",
            queue.servers()
        ),
        None => broker.to_string(),
    };
    writeln!(
        out,
        "fleet service: reports from {source} into {}; campaigns {}",
        store.name(),
        if key.is_some() {
            "sent"
        } else {
            "not sent (no --key)"
        }
    )
    .map_err(io)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Ctrl-C and SIGTERM (a service manager's stop). A second service or a test may
        // have set a handler: then they just end the process.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let started = Instant::now();
    let ingest = match queue {
        Some(queue) => Ingest::with_queue(store, link, queue),
        None => Ingest::new(store, link),
    };
    let mut service = FleetService::new(ingest, key, Duration::from_secs_f64(tick));
    while !stop.load(Ordering::Relaxed)
        && duration.is_none_or(|d| started.elapsed().as_secs_f64() < d)
    {
        service.step(&stop, Duration::from_millis(50));
        // As they happen, so an operator sees a database that fails, and its return.
        for notice in service.ingest.take_notices() {
            eprintln!("fleet: {notice}");
        }
    }
    // Leaving the group before going: no new reports come, and what the broker had sent
    // already is stored and acknowledged (with a session ended at disconnect, anything
    // unacknowledged would wait for the cars' resend).
    let drained = service.ingest.leave(&subscription, DRAIN_QUIET);
    if drained > 0 {
        eprintln!("fleet: took {drained} reports that had arrived before leaving the group");
    }
    let sends = service.sends_campaigns();
    let (sent, failure) = (service.sent, service.failure.take());
    let ingest = service.ingest;
    let s = &ingest.stats;
    writeln!(
        out,
        "stored {} inventories, {} trips ({} duplicates), {} campaign reports; refused {}",
        s.inventories, s.trips, s.duplicates, s.campaign_reports, s.rejected
    )
    .map_err(io)?;
    for reason in &s.last_rejections {
        writeln!(out, "  refused: {reason}").map_err(io)?;
    }
    if sends {
        writeln!(out, "sent {sent} campaign instructions").map_err(io)?;
    }
    if let Some(failure) = failure {
        writeln!(out, "last campaign error: {failure}").map_err(io)?;
    }
    ingest.link.close(Duration::from_secs(5));
    Ok(())
}

/// Reads the fleet's signing key (`autoplug keygen`'s FILE.key).
fn read_key(path: &Path) -> Result<SigningKey, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read the key '{}': {e}", path.display()))?;
    SigningKey::parse(&text).map_err(|e| format!("'{}': {e}", path.display()))
}
