//! The broker's configuration for a fleet, shipped with the project (`fleet/broker/`):
//! Mosquitto with logins, the ACL that keeps each vehicle to its own topics, persistent
//! sessions, and two listeners: the vehicles' (a car's client id is its login) and the
//! fleet services' (each process its own client id under the fleet's login). [`init`]
//! writes a ready directory; [`add_login`] adds a vehicle (or the fleet services' login)
//! to its listener's password file with Mosquitto's own `mosquitto_passwd`, so the
//! password is hashed exactly as the broker expects.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The broker configuration, with `{dir}`, `{bind}`, `{port}`, `{fleet_bind}`,
/// `{fleet_port}` and `{user}` to fill in.
pub const CONFIG_TEMPLATE: &str = include_str!("../broker/mosquitto.conf");

/// The ACL (see the file's comments).
pub const ACL: &str = include_str!("../broker/acl");

/// The fleet services' user name (the ACL grants it every fleet topic).
pub const FLEET_USER: &str = "autoplug-fleet";

/// Files of a broker directory.
#[derive(Clone, Debug)]
pub struct BrokerDir {
    /// The directory.
    pub dir: PathBuf,
    /// `mosquitto.conf`.
    pub config: PathBuf,
    /// `passwd`: the vehicles' logins.
    pub passwords: PathBuf,
    /// `passwd-fleet`: the fleet services' login.
    pub fleet_passwords: PathBuf,
}

impl BrokerDir {
    /// The files of `dir` (written or not).
    pub fn at(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            config: dir.join("mosquitto.conf"),
            passwords: dir.join("passwd"),
            fleet_passwords: dir.join("passwd-fleet"),
        }
    }

    /// The password file that holds `user`'s login: the fleet's own, or the vehicles'.
    pub fn passwords_of(&self, user: &str) -> &Path {
        if user == FLEET_USER {
            &self.fleet_passwords
        } else {
            &self.passwords
        }
    }
}

/// Writes a broker directory: `mosquitto.conf` listening for vehicles on `bind:port` and
/// for the fleet services on `fleet_bind:fleet_port`, the ACL, two empty password files
/// (mode 0600) and the persistence directory. Refuses to overwrite a configuration that is
/// there (its password files hold logins).
pub fn init(
    dir: &Path,
    bind: &str,
    port: u16,
    fleet_bind: &str,
    fleet_port: u16,
) -> Result<BrokerDir, String> {
    for address in [bind, fleet_bind] {
        if address.is_empty() || address.contains(char::is_whitespace) {
            return Err(format!("'{address}' is not an address to listen on"));
        }
    }
    if port == fleet_port {
        return Err(format!(
            "the vehicles and the fleet services need a port each (both are {port})"
        ));
    }
    let files = BrokerDir::at(dir);
    if files.config.exists() {
        return Err(format!(
            "{} exists already: a broker directory is written once (its password file holds the logins)",
            files.config.display()
        ));
    }
    let abs =
        std::path::absolute(dir).map_err(|e| format!("cannot resolve '{}': {e}", dir.display()))?;
    let text = abs.to_str().ok_or_else(|| {
        format!(
            "'{}' is not valid UTF-8 (Mosquitto reads paths as text)",
            abs.display()
        )
    })?;
    if text.contains(char::is_whitespace) {
        return Err(format!(
            "'{text}' holds spaces, which Mosquitto's configuration cannot"
        ));
    }
    let data = dir.join("data");
    std::fs::create_dir_all(&data)
        .map_err(|e| format!("cannot create '{}': {e}", data.display()))?;
    let config = CONFIG_TEMPLATE
        .replace("{user}", &owner_name(&abs))
        .replace("{dir}", text)
        .replace("{fleet_bind}", fleet_bind)
        .replace("{fleet_port}", &fleet_port.to_string())
        .replace("{bind}", bind)
        .replace("{port}", &port.to_string());
    let write = |path: &Path, body: &str, mode: u32| -> Result<(), String> {
        std::fs::write(path, body)
            .map_err(|e| format!("cannot write '{}': {e}", path.display()))?;
        set_mode(path, mode)
    };
    write(&dir.join("acl"), ACL, 0o644)?;
    write(&files.passwords, "", 0o600)?;
    write(&files.fleet_passwords, "", 0o600)?;
    write(&files.config, &config, 0o644)?;
    Ok(files)
}

/// The account owning `dir`, by name: a broker started as root drops to it and can still
/// read the password file (mode 0600) and write its persistence. `mosquitto` (the
/// package's account) if the name cannot be found.
#[cfg(unix)]
fn owner_name(dir: &Path) -> String {
    use std::os::unix::fs::MetadataExt;
    let Ok(uid) = std::fs::metadata(dir).map(|m| m.uid()) else {
        return "mosquitto".into();
    };
    // /etc/passwd: name:password:uid:... (no NSS lookup without libc; a directory
    // account from LDAP falls back to the default).
    std::fs::read_to_string("/etc/passwd")
        .ok()
        .and_then(|passwd| {
            passwd.lines().find_map(|line| {
                let mut fields = line.split(':');
                let name = fields.next()?;
                let uid_field = fields.nth(1)?;
                (uid_field.parse::<u32>().ok()? == uid).then(|| name.to_string())
            })
        })
        .unwrap_or_else(|| "mosquitto".into())
}

#[cfg(not(unix))]
fn owner_name(_dir: &Path) -> String {
    "mosquitto".into()
}

#[cfg(unix)]
fn set_mode(path: &Path, mode: u32) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(|e| format!("cannot set the mode of '{}': {e}", path.display()))
}

#[cfg(not(unix))]
fn set_mode(_path: &Path, _mode: u32) -> Result<(), String> {
    Ok(())
}

/// A fresh random password: 24 bytes as hex (192 bits).
pub fn random_password() -> Result<String, String> {
    let mut bytes = [0u8; 24];
    getrandom::fill(&mut bytes).map_err(|e| format!("no randomness for a password: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Where `mosquitto_passwd` is: `$MOSQUITTO_PASSWD`, else on the `PATH`.
fn mosquitto_passwd() -> PathBuf {
    std::env::var_os("MOSQUITTO_PASSWD")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("mosquitto_passwd"))
}

/// Adds (or changes) a login in the directory's password file for it (the fleet services'
/// for [`FLEET_USER`], the vehicles' for any other). A running broker reads it again on
/// SIGHUP.
pub fn add_login(dir: &BrokerDir, user: &str, password: &str) -> Result<(), String> {
    // The password file's format separates user and hash with ':'; the ACL's patterns
    // take the name into topics.
    if user.is_empty() || user.contains([':', '/', '+', '#']) || user.chars().any(char::is_control)
    {
        return Err(format!(
            "'{user}' cannot be a broker login (no ':', '/', '+', '#')"
        ));
    }
    let passwords = dir.passwords_of(user);
    if !passwords.exists() {
        return Err(format!(
            "{} does not exist: write the directory first (autoplug fleet broker init)",
            passwords.display()
        ));
    }
    let tool = mosquitto_passwd();
    let output = Command::new(&tool)
        .arg("-b")
        .arg(passwords)
        .arg(user)
        .arg(password)
        .output()
        .map_err(|e| {
            format!(
                "cannot run {} (Mosquitto's password tool, in the mosquitto package): {e}",
                tool.display()
            )
        })?;
    if !output.status.success() {
        return Err(format!(
            "{} failed: {}",
            tool.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broker_directory_is_written_once_with_every_placeholder_filled() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("broker");
        let files = init(&dir, "127.0.0.1", 18830, "127.0.0.1", 18831).unwrap();
        let config = std::fs::read_to_string(&files.config).unwrap();
        assert!(!config.contains('{'), "{config}");
        assert!(config.contains("listener 18830 127.0.0.1"));
        assert!(config.contains("listener 18831 127.0.0.1"));
        assert!(files.fleet_passwords.exists());
        assert_eq!(files.passwords_of(FLEET_USER), files.fleet_passwords);
        assert!(config.contains("allow_anonymous false"));
        assert!(config.contains(&format!("acl_file {}/acl", dir.display())));
        assert_eq!(std::fs::read_to_string(dir.join("acl")).unwrap(), ACL);
        let again = init(&dir, "127.0.0.1", 18830, "127.0.0.1", 18831).unwrap_err();
        assert!(again.contains("exists already"), "{again}");
        assert!(init(&tmp.path().join("b2"), "", 1, "127.0.0.1", 2).is_err());
        assert!(init(&tmp.path().join("b3"), "127.0.0.1", 1, "127.0.0.1", 1).is_err());
        assert!(add_login(&files, "a:b", "x")
            .unwrap_err()
            .contains("cannot be a broker login"));
    }

    #[test]
    fn passwords_are_random() {
        let (a, b) = (random_password().unwrap(), random_password().unwrap());
        assert_eq!(a.len(), 48);
        assert_ne!(a, b);
    }
}
