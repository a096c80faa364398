//! `autoplug fleet broker init` and `autoplug fleet broker add`: the broker's configuration
//! and logins, Mosquitto's or a NATS cluster's.

use std::io::Write;
use std::net::SocketAddr;
use std::path::Path;

use autoplug_fleet::{broker, nats_cluster};

use super::io;

/// Writes the broker's configuration into `dir` and says how to run it.
pub(crate) fn init(
    dir: &Path,
    listen: SocketAddr,
    fleet_listen: SocketAddr,
    out: &mut dyn Write,
) -> Result<(), String> {
    let files = broker::init(
        dir,
        &listen.ip().to_string(),
        listen.port(),
        &fleet_listen.ip().to_string(),
        fleet_listen.port(),
    )?;
    writeln!(
        out,
        "wrote {} (with the logins' file, dynamic-security.json, and the administrator's password): vehicles on {listen}, fleet services on {fleet_listen}\nrun it with: mosquitto -c {}\nthen add logins with: autoplug fleet broker add --dir {} --user VIN (or --user {})",
        files.config.display(),
        files.config.display(),
        dir.display(),
        broker::FLEET_USER
    )
    .map_err(io)?;
    Ok(())
}

/// Writes a NATS cluster's configuration into `dir`: `nodes` nodes on one machine, node N
/// on each port plus N-1, and says how to run it.
pub(crate) fn init_nats(
    dir: &Path,
    nodes: usize,
    listen: SocketAddr,
    client_listen: SocketAddr,
    cluster_listen: SocketAddr,
    out: &mut dyn Write,
) -> Result<(), String> {
    let host = listen.ip().to_string();
    for other in [client_listen, cluster_listen] {
        if other.ip() != listen.ip() {
            return Err(format!(
                "the nodes of one machine listen on one address ({host}, not {}): for nodes on machines of their own, edit each node's listen addresses and routes",
                other.ip()
            ));
        }
    }
    let addresses = nats_cluster::local_nodes(
        &host,
        nodes,
        listen.port(),
        client_listen.port(),
        cluster_listen.port(),
    )?;
    let files = nats_cluster::init(dir, &addresses)?;
    let mqtt: Vec<String> = addresses
        .iter()
        .map(|a| format!("{}:{}", a.host, a.mqtt_port))
        .collect();
    let clients: Vec<String> = addresses
        .iter()
        .map(|a| format!("{}:{}", a.host, a.client_port))
        .collect();
    writeln!(
        out,
        "wrote {nodes} NATS node configurations in {} (with the logins' files, logins.json and users.conf)",
        dir.display()
    )
    .map_err(io)?;
    for config in files.node_configs() {
        writeln!(out, "run: nats-server -c {}", config.display()).map_err(io)?;
    }
    writeln!(
        out,
        "then add logins with: autoplug fleet broker add --dir {} --user VIN (or --user {})
vehicles: --fleet mqtt://VIN:PASSWORD@{}
services: autoplug fleet serve --broker mqtt://{}:PASSWORD@{} --queue nats://{}:PASSWORD@{}",
        dir.display(),
        broker::FLEET_USER,
        mqtt.join(","),
        broker::FLEET_USER,
        mqtt.join(","),
        broker::FLEET_USER,
        clients.join(","),
    )
    .map_err(io)?;
    Ok(())
}

/// Adds a login (or a new password for one) to the running broker; prints a password it
/// made up.
pub(crate) fn add(
    dir: &Path,
    user: &str,
    password_file: Option<&Path>,
    out: &mut dyn Write,
) -> Result<(), String> {
    let (password, show) = match password_file {
        Some(path) => (
            std::fs::read_to_string(path)
                .map_err(|e| format!("cannot read '{}': {e}", path.display()))?
                .trim_end_matches(['\r', '\n'])
                .to_string(),
            false,
        ),
        None => (broker::random_password()?, true),
    };
    let cluster = nats_cluster::ClusterDir::at(dir);
    if cluster.logins.is_file() {
        let told =
            nats_cluster::add_logins(&cluster, &[(user.to_string(), password.clone(), !show)])?;
        writeln!(
            out,
            "added {user} to {} ({told} running nodes told to reload; nodes elsewhere need this users.conf and a reload)",
            cluster.users.display()
        )
        .map_err(io)?;
    } else {
        broker::add_login(&broker::BrokerDir::at(dir), user, &password)?;
        writeln!(out, "added {user} to the running broker").map_err(io)?;
    }
    if show {
        writeln!(out, "password: {password}").map_err(io)?;
    }
    Ok(())
}
