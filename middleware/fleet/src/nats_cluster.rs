//! The clustered engine's configuration: NATS nodes (JetStream, MQTT for the cars) and
//! their logins, written by `autoplug fleet broker init --engine nats`.
//!
//! A directory holds one configuration per node (`node-1.conf` …), each node's JetStream
//! store, and the logins: `logins.json` (the source: each login's bcrypt hash, written
//! only here) and `users.conf` (made from it, included by every node). Adding a login
//! rewrites both and tells the running nodes of this directory to reload (SIGHUP): no
//! restart, no car disconnected. Nodes on other machines get the same `users.conf` and a
//! reload of their own.
//!
//! The rights are NATS's per-subject permissions, the same as the Mosquitto set-up's:
//! a vehicle's login is its VIN; it may publish only under its own
//! `autoplug.v1.vehicles.VIN.report`, subscribe only to its own `…VIN.command` and to the
//! images (and to `$MQTT.sub.>`, the delivery subjects of its own QoS 1 subscriptions,
//! which the server keeps from MQTT topics). NATS does not bind an MQTT client id to a
//! login; a car's client id carries a tag only its password makes
//! ([`crate::mqtt::vehicle_client_id`]), so no car can name another's session, and one that
//! did would still read nothing of the other car's: the session's subscriptions are
//! checked against its own rights (tested: `tests/nats_engine.rs`).

use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use crate::broker::{random_password, FLEET_USER};

/// The cluster's name (routes of another cluster are refused).
pub const CLUSTER_NAME: &str = "autoplug";

/// The login the nodes use between them (routes).
pub const ROUTE_USER: &str = "autoplug-route";

/// bcrypt's cost for a stored password. The passwords this project makes are 192 random
/// bits, which no cost makes stronger, and every node checks a car's password at each
/// connect (a thousand cars reconnecting after a node failure): the minimum keeps that at
/// about a millisecond each. A password chosen by a person (`--password-file`) gets
/// [`CHOSEN_PASSWORD_COST`].
pub const RANDOM_PASSWORD_COST: u32 = 4;

/// See [`RANDOM_PASSWORD_COST`].
pub const CHOSEN_PASSWORD_COST: u32 = 10;

/// Where a node listens.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeAddress {
    /// The address its three listeners bind to.
    pub host: String,
    /// The cars' MQTT port.
    pub mqtt_port: u16,
    /// NATS clients' port (the fleet services).
    pub client_port: u16,
    /// The other nodes' port (routes).
    pub cluster_port: u16,
}

/// Files of a cluster directory.
#[derive(Clone, Debug)]
pub struct ClusterDir {
    /// The directory.
    pub dir: PathBuf,
    /// `logins.json`: every login's bcrypt hash and rights' kind.
    pub logins: PathBuf,
    /// `users.conf`: the logins as the nodes read them.
    pub users: PathBuf,
}

impl ClusterDir {
    /// The files of `dir` (written or not).
    pub fn at(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            logins: dir.join("logins.json"),
            users: dir.join("users.conf"),
        }
    }

    /// Node `n`'s configuration (from 1).
    pub fn node_config(&self, n: usize) -> PathBuf {
        self.dir.join(format!("node-{n}.conf"))
    }

    /// Node `n`'s process id file (while it runs).
    pub fn node_pid(&self, n: usize) -> PathBuf {
        self.dir.join(format!("node-{n}.pid"))
    }

    /// The nodes' configurations there, in order.
    pub fn node_configs(&self) -> Vec<PathBuf> {
        (1..)
            .map(|n| self.node_config(n))
            .take_while(|p| p.is_file())
            .collect()
    }
}

/// The addresses of `nodes` nodes on one machine: node `i` (from 0) on the given ports
/// plus `i`. Nodes on machines of their own keep the same ports: edit the `routes`.
pub fn local_nodes(
    host: &str,
    nodes: usize,
    mqtt_port: u16,
    client_port: u16,
    cluster_port: u16,
) -> Result<Vec<NodeAddress>, String> {
    if nodes == 0 {
        return Err("a cluster needs one node at least".into());
    }
    let port = |base: u16, i: usize| {
        u16::try_from(i)
            .ok()
            .and_then(|i| base.checked_add(i))
            .ok_or_else(|| format!("port {base} + {i} is beyond 65535"))
    };
    let mut addresses = Vec::new();
    for i in 0..nodes {
        addresses.push(NodeAddress {
            host: host.to_string(),
            mqtt_port: port(mqtt_port, i)?,
            client_port: port(client_port, i)?,
            cluster_port: port(cluster_port, i)?,
        });
    }
    let mut ports: Vec<u16> = addresses
        .iter()
        .flat_map(|a| [a.mqtt_port, a.client_port, a.cluster_port])
        .collect();
    ports.sort_unstable();
    if ports.windows(2).any(|w| w[0] == w[1]) {
        return Err(format!(
            "the ports of {nodes} nodes overlap (MQTT from {mqtt_port}, clients from {client_port}, routes from {cluster_port}): leave {nodes} ports between each"
        ));
    }
    Ok(addresses)
}

/// A quoted string for the nodes' configuration.
fn quoted(text: &str) -> String {
    serde_json::to_string(text).unwrap_or_else(|_| "\"\"".into())
}

/// A password as the nodes check it: bcrypt, in the `$2a$` form every NATS release reads.
pub fn bcrypt_hash(password: &str, cost: u32) -> Result<String, String> {
    bcrypt::hash_with_result(password, cost)
        .map(|h| h.format_for_version(bcrypt::Version::TwoA))
        .map_err(|e| format!("cannot hash a password: {e}"))
}

/// Writes a cluster directory of `nodes` (one node: no routes). Refuses to overwrite one
/// that is there (it holds the logins).
pub fn init(dir: &Path, nodes: &[NodeAddress]) -> Result<ClusterDir, String> {
    if nodes.is_empty() {
        return Err("a cluster needs one node at least".into());
    }
    for node in nodes {
        if node.host.is_empty() || node.host.contains(|c: char| c.is_whitespace() || c == '"') {
            return Err(format!("'{}' is not an address to listen on", node.host));
        }
    }
    let files = ClusterDir::at(dir);
    if files.logins.exists() || files.node_config(1).exists() {
        return Err(format!(
            "{} exists already: a cluster directory is written once (it holds the logins)",
            files.logins.display()
        ));
    }
    let abs =
        std::path::absolute(dir).map_err(|e| format!("cannot resolve '{}': {e}", dir.display()))?;
    let text = abs.to_str().ok_or_else(|| {
        format!(
            "'{}' is not valid UTF-8 (NATS reads paths as text)",
            abs.display()
        )
    })?;
    std::fs::create_dir_all(&abs).map_err(|e| format!("cannot create '{text}': {e}"))?;
    let route_password = random_password()?;
    let route_hash = bcrypt_hash(&route_password, RANDOM_PASSWORD_COST)?;
    for (i, node) in nodes.iter().enumerate() {
        let n = i + 1;
        let mut config = format!(
            "# AutoPlug fleet: NATS node {n} of {count}, written by `autoplug fleet broker init --engine nats`.\n\
             # Cars speak MQTT to the mqtt listener (their logins and rights: users.conf); the\n\
             # fleet services take the reports from JetStream on the client listener.\n\
             server_name: {name}\n\
             listen: {client}\n\
             pid_file: {pid}\n\
             # A signed image (an ECU slot is 112 KiB) with room to spare.\n\
             max_payload: 1MB\n\
             \n\
             jetstream {{\n  store_dir: {store}\n}}\n\
             \n\
             mqtt {{\n  listen: {mqtt}\n  # The cars' sessions and QoS 1 messages on as many nodes as the reports: a node lost\n  # keeps a majority (the server would pick fewer if it started before its peers).\n  stream_replicas: {replicas}\n}}\n\
             \n\
             authorization {{\n  include \"users.conf\"\n}}\n",
            count = nodes.len(),
            name = quoted(&format!("autoplug-{n}")),
            client = quoted(&format!("{}:{}", node.host, node.client_port)),
            pid = quoted(&format!("{text}/node-{n}.pid")),
            store = quoted(&format!("{text}/node-{n}")),
            mqtt = quoted(&format!("{}:{}", node.host, node.mqtt_port)),
            replicas = nodes.len().min(3),
        );
        if nodes.len() > 1 {
            let routes: Vec<String> = nodes
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, other)| {
                    quoted(&format!(
                        "nats-route://{ROUTE_USER}:{route_password}@{}:{}",
                        other.host, other.cluster_port
                    ))
                })
                .collect();
            config.push_str(&format!(
                "\n# The other nodes (RAFT replicates the streams between them); only nodes that\n\
                 # know the routes' password join.\n\
                 cluster {{\n  name: {cluster}\n  listen: {listen}\n  authorization {{\n    user: {user}\n    password: {hash}\n  }}\n  routes: [\n    {routes}\n  ]\n}}\n",
                cluster = quoted(CLUSTER_NAME),
                listen = quoted(&format!("{}:{}", node.host, node.cluster_port)),
                user = quoted(ROUTE_USER),
                hash = quoted(&route_hash),
                routes = routes.join("\n    "),
            ));
        }
        let path = files.node_config(n);
        // The routes' password stands in it: readable by the owner only.
        write_private(&path, &config)?;
    }
    write_logins(&files, &[])?;
    Ok(files)
}

fn write_private(path: &Path, body: &str) -> Result<(), String> {
    std::fs::write(path, body).map_err(|e| format!("cannot write '{}': {e}", path.display()))?;
    crate::broker::set_mode(path, 0o600)
}

/// A login's permissions in the nodes' configuration: a vehicle's own subjects; the fleet
/// services' login every subject of the account (reports, receipts, instructions, images,
/// the JetStream API and its acknowledgements).
fn permissions(user: &str) -> Result<Option<String>, String> {
    if user == FLEET_USER {
        return Ok(None);
    }
    let vin = autoplug_vin::Vin::parse(user)
        .map_err(|e| format!("'{user}' is neither a VIN ({e}) nor {FLEET_USER}"))?;
    let own = format!("autoplug.v1.vehicles.{vin}");
    let list = |subjects: &[String]| {
        subjects
            .iter()
            .map(|s| quoted(s))
            .collect::<Vec<_>>()
            .join(", ")
    };
    Ok(Some(format!(
        "{{ publish: {{ allow: [{}] }}, subscribe: {{ allow: [{}] }} }}",
        list(&[format!("{own}.report.>")]),
        list(&[
            format!("{own}.command"),
            format!("{own}.command.>"),
            "autoplug.v1.images".into(),
            "autoplug.v1.images.>".into(),
            "$MQTT.sub.>".into(),
        ]),
    )))
}

fn read_logins(files: &ClusterDir) -> Result<Vec<(String, String)>, String> {
    let text = std::fs::read_to_string(&files.logins).map_err(|e| {
        format!(
            "cannot read {} (write the directory first: autoplug fleet broker init --engine nats): {e}",
            files.logins.display()
        )
    })?;
    let value: Value = serde_json::from_str(&text)
        .map_err(|e| format!("{} is damaged: {e}", files.logins.display()))?;
    value["logins"]
        .as_array()
        .ok_or_else(|| format!("{} holds no logins list", files.logins.display()))?
        .iter()
        .map(|l| match (l["user"].as_str(), l["bcrypt"].as_str()) {
            (Some(user), Some(hash)) => Ok((user.to_string(), hash.to_string())),
            _ => Err(format!(
                "{} holds a login without user or hash",
                files.logins.display()
            )),
        })
        .collect()
}

/// Writes `logins.json` and `users.conf` (a new file each, renamed over the old: a node
/// reloading meanwhile reads one or the other, never half).
fn write_logins(files: &ClusterDir, logins: &[(String, String)]) -> Result<(), String> {
    let mut users = String::from(
        "# The fleet's logins, made from logins.json by `autoplug fleet broker add`.\nusers = [\n",
    );
    for (user, hash) in logins {
        users.push_str(&format!(
            "  {{ user: {}, password: {}",
            quoted(user),
            quoted(hash)
        ));
        if let Some(permissions) = permissions(user)? {
            users.push_str(&format!(", permissions: {permissions}"));
        }
        users.push_str(" }\n");
    }
    users.push_str("]\n");
    let json = json!({
        "logins": logins
            .iter()
            .map(|(user, hash)| json!({ "user": user, "bcrypt": hash }))
            .collect::<Vec<_>>()
    });
    let json = serde_json::to_string_pretty(&json)
        .map_err(|e| format!("cannot encode the logins: {e}"))?;
    for (path, body) in [(&files.logins, json), (&files.users, users)] {
        let new = path.with_extension("new");
        write_private(&new, &body)?;
        std::fs::rename(&new, path)
            .map_err(|e| format!("cannot replace '{}': {e}", path.display()))?;
    }
    Ok(())
}

/// Adds logins (user, password, chosen by a person) to the directory, a login there
/// already getting the new password, and tells the nodes of this directory that run to
/// reload them. Returns how many nodes were told.
pub fn add_logins(files: &ClusterDir, logins: &[(String, String, bool)]) -> Result<usize, String> {
    let mut all = read_logins(files)?;
    for (user, password, chosen) in logins {
        permissions(user)?;
        if password.is_empty() {
            return Err(format!("an empty password for {user}"));
        }
        let cost = if *chosen {
            CHOSEN_PASSWORD_COST
        } else {
            RANDOM_PASSWORD_COST
        };
        let hash = bcrypt_hash(password, cost)?;
        match all.iter_mut().find(|(u, _)| u == user) {
            Some(entry) => entry.1 = hash,
            None => all.push((user.clone(), hash)),
        }
    }
    write_logins(files, &all)?;
    reload(files)
}

/// Sends SIGHUP (reload the configuration) to every node of `files` that runs (its pid
/// file names a live process). Returns how many.
pub fn reload(files: &ClusterDir) -> Result<usize, String> {
    let mut told = 0;
    for n in 1..=files.node_configs().len() {
        let Ok(pid) = std::fs::read_to_string(files.node_pid(n)) else {
            continue;
        };
        let pid = pid.trim();
        if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        // A pid file left by a node that ended may name another process by now: only a
        // running nats-server is told.
        let command = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
        if cfg!(target_os = "linux") && command.trim() != "nats-server" {
            continue;
        }
        let status = std::process::Command::new("kill")
            .args(["-HUP", pid])
            .stderr(std::process::Stdio::null())
            .status()
            .map_err(|e| format!("cannot run kill: {e}"))?;
        if status.success() {
            told += 1;
        }
    }
    Ok(told)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cluster_directory_is_written_once_with_routes_between_its_nodes() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("nats");
        let nodes = local_nodes("127.0.0.1", 3, 11883, 14222, 16222).unwrap();
        let files = init(&dir, &nodes).unwrap();
        assert_eq!(files.node_configs().len(), 3);
        let second = std::fs::read_to_string(files.node_config(2)).unwrap();
        assert!(second.contains("listen: \"127.0.0.1:14223\""), "{second}");
        assert!(second.contains("listen: \"127.0.0.1:11884\""), "{second}");
        assert!(second.contains("@127.0.0.1:16222\"") && second.contains("@127.0.0.1:16224\""));
        assert!(
            !second.contains("@127.0.0.1:16223\""),
            "no route to itself: {second}"
        );
        assert!(init(&dir, &nodes).unwrap_err().contains("exists already"));
        let vin = "JA3AP47H0YF000042";
        add_logins(
            &files,
            &[
                (vin.into(), "pw".into(), false),
                (FLEET_USER.into(), "fleet-pw".into(), false),
            ],
        )
        .unwrap();
        let users = std::fs::read_to_string(&files.users).unwrap();
        assert!(
            users.contains(&format!("\"autoplug.v1.vehicles.{vin}.report.>\"")),
            "{users}"
        );
        assert!(
            !users.contains("fleet-pw") && !users.contains("\"pw\""),
            "{users}"
        );
        // A new password replaces the old; a bad user changes nothing.
        add_logins(&files, &[(vin.into(), "pw2".into(), true)]).unwrap();
        let logins = read_logins(&files).unwrap();
        assert_eq!(logins.len(), 2);
        assert!(bcrypt::verify("pw2", &logins[0].1).unwrap());
        assert!(logins[0].1.starts_with("$2a$10$"));
        assert!(add_logins(&files, &[("a b".into(), "x".into(), false)])
            .unwrap_err()
            .contains("neither a VIN"));
        assert_eq!(read_logins(&files).unwrap().len(), 2);
        assert!(local_nodes("127.0.0.1", 3, 1000, 1001, 2000)
            .unwrap_err()
            .contains("overlap"));
    }
}
