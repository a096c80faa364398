//! What the page shows of the GDB servers on the virtual car's emulated ECUs (`--gdb`):
//! watched from a thread of its own, because the session's thread stands still with the
//! car while a debugger holds an ECU halted.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use autoplug_can::ecu_name;
use autoplug_virtual_car::firmware::DebugPorts;
use autoplug_web::LiveTable;

/// How often the servers' statuses are looked at: a halt shows on the page within this
/// (and the stream's own 50 ms).
pub const WATCH_PERIOD: Duration = Duration::from_millis(50);

/// The thread that publishes the debuggers' statuses into the live table; stops when
/// dropped.
pub struct DebuggerWatch {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl DebuggerWatch {
    /// Publishes `ports`' statuses into `table` every [`WATCH_PERIOD`] (nothing to watch
    /// without ports: no thread).
    pub fn start(ports: DebugPorts, table: Arc<LiveTable>) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let thread = (!ports.is_empty()).then(|| {
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("debugger-watch".into())
                .spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        table.set_debugger(&statuses(&ports));
                        std::thread::sleep(WATCH_PERIOD);
                    }
                })
                .ok()
        });
        Self {
            stop,
            thread: thread.flatten(),
        }
    }
}

impl Drop for DebuggerWatch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The stream's `debugger` object (see `autoplug_web`'s crate docs).
pub fn statuses(ports: &DebugPorts) -> serde_json::Value {
    let ecus: Vec<serde_json::Value> = ports
        .iter()
        .map(|(node, status)| {
            let attached = status.attached();
            serde_json::json!({
                "ecu": ecu_name(*node),
                "address": status.address().to_string(),
                "attached": attached,
                "halted": attached && status.halted(),
                "client": status.peer().filter(|_| attached).map(|p| p.to_string()),
            })
        })
        .collect();
    serde_json::json!({ "ecus": ecus })
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::Node;
    use autoplug_mcu::gdb::GdbServer;

    #[test]
    fn the_watch_publishes_each_server_and_stops_when_dropped() {
        let server = GdbServer::bind("cruise", "127.0.0.1:0".parse().unwrap()).unwrap();
        let address = server.local_addr().to_string();
        let ports = vec![(Node::Cruise, server.status())];
        let table = Arc::new(LiveTable::new());
        let watch = DebuggerWatch::start(ports, Arc::clone(&table));
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        let published = loop {
            let (update, _) = table.update_since(0);
            let update: serde_json::Value = serde_json::from_str(&update).unwrap();
            if !update["debugger"].is_null() {
                break update["debugger"].clone();
            }
            assert!(std::time::Instant::now() < deadline, "nothing published");
            std::thread::sleep(WATCH_PERIOD);
        };
        assert_eq!(
            published,
            serde_json::json!({"ecus": [{"ecu": "cruise", "address": address,
                "attached": false, "halted": false, "client": null}]})
        );
        assert!(table.halted_by_debugger().is_empty());
        drop(watch);
        // Nothing to watch: no thread, nothing published.
        let empty = Arc::new(LiveTable::new());
        drop(DebuggerWatch::start(Vec::new(), Arc::clone(&empty)));
        assert!(!empty.update_since(0).0.contains("debugger"));
    }
}
