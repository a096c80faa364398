//! `autoplug fleet broker init` and `autoplug fleet broker add`: the Mosquitto broker's
//! configuration and logins.

use std::io::Write;
use std::net::SocketAddr;
use std::path::Path;

use autoplug_fleet::broker;

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
    broker::add_login(&broker::BrokerDir::at(dir), user, &password)?;
    writeln!(out, "added {user} to the running broker").map_err(io)?;
    if show {
        writeln!(out, "password: {password}").map_err(io)?;
    }
    Ok(())
}
