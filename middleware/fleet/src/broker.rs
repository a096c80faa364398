//! The broker's configuration for a fleet, shipped with the project (`middleware/fleet/broker/`):
//! Mosquitto with its dynamic-security plugin holding the logins and their rights,
//! persistent sessions, and two listeners (the vehicles' and the fleet services').
//!
//! The rights (see the configuration's comments): a vehicle's login is its VIN, bound to
//! its own client id (its VIN and a tag only its password makes:
//! [`crate::mqtt::vehicle_client_id`]), with a role of its own that lets it publish its reports, and
//! subscribe to its own commands and receipts and to the images, and nothing else: a
//! SUBSCRIBE to anything more is refused at once, the fleet services' shared group above
//! all (Mosquitto's ACL file granted it, and the car then took its turn of every car's
//! reports). The fleet's processes share one login and choose their client ids.
//!
//! [`init`] writes a ready directory (the plugin's file with an administrator login, whose
//! password stays in the directory); [`add_logins`] adds vehicles, or the fleet services'
//! login, to the running broker through the plugin's control topic, as Mosquitto's own
//! `mosquitto_ctrl` does, so the broker never needs a restart for a new car.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use crate::mqtt::{Broker, LinkOptions, MqttLink};

/// The broker configuration, with `{dir}`, `{bind}`, `{port}`, `{fleet_bind}`,
/// `{fleet_port}`, `{plugin}` and `{user}` to fill in.
pub const CONFIG_TEMPLATE: &str = include_str!("../broker/mosquitto.conf");

/// The fleet services' user name.
pub const FLEET_USER: &str = "autoplug-fleet";

/// The login that administers the logins (the plugin's control topic only).
pub const ADMIN_USER: &str = "autoplug-admin";

/// The plugin's control topic and where it answers.
const CONTROL: &str = "$CONTROL/dynamic-security/v1";
const CONTROL_RESPONSE: &str = "$CONTROL/dynamic-security/v1/response";

/// PBKDF2-SHA512 rounds of a stored password: the plugin's own default. The passwords
/// this module makes are 192 random bits, which no number of rounds makes stronger.
const PASSWORD_ROUNDS: u32 = 101;

/// The role every vehicle has besides its own: the images.
const VEHICLES_GROUP: &str = "vehicles";

/// Files of a broker directory.
#[derive(Clone, Debug)]
pub struct BrokerDir {
    /// The directory.
    pub dir: PathBuf,
    /// `mosquitto.conf`.
    pub config: PathBuf,
    /// `dynamic-security.json`: the logins and their rights (the broker's own file while
    /// it runs: change it through [`add_logins`]).
    pub security: PathBuf,
    /// `admin-password`: the administrator's password (mode 0600).
    pub admin_password: PathBuf,
}

impl BrokerDir {
    /// The files of `dir` (written or not).
    pub fn at(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            config: dir.join("mosquitto.conf"),
            security: dir.join("dynamic-security.json"),
            admin_password: dir.join("admin-password"),
        }
    }

    /// The fleet services' listener, as the configuration names it (its second
    /// `listener` line): where `add_logins` talks to the broker.
    pub fn fleet_listener(&self) -> Result<(String, u16), String> {
        let text = std::fs::read_to_string(&self.config).map_err(|e| {
            format!(
                "cannot read {} (write the directory first: autoplug fleet broker init): {e}",
                self.config.display()
            )
        })?;
        let listener = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix("listener "))
            .nth(1)
            .ok_or_else(|| {
                format!(
                    "{} names no second listener (the fleet's)",
                    self.config.display()
                )
            })?;
        let mut parts = listener.split_whitespace();
        let port = parts
            .next()
            .and_then(|p| p.parse::<u16>().ok())
            .ok_or_else(|| format!("{}: 'listener {listener}'", self.config.display()))?;
        // A broker listening on every address is reached on this machine's loopback.
        let host = match parts.next() {
            None | Some("0.0.0.0") => "127.0.0.1".to_string(),
            Some("::") => "::1".to_string(),
            Some(host) => host.to_string(),
        };
        Ok((host, port))
    }
}

/// Where Mosquitto's dynamic-security plugin is: `$MOSQUITTO_DYNSEC_PLUGIN`, else where
/// the distributions put it.
pub fn find_plugin() -> Result<PathBuf, String> {
    if let Some(path) = std::env::var_os("MOSQUITTO_DYNSEC_PLUGIN") {
        return Ok(PathBuf::from(path));
    }
    const NAME: &str = "mosquitto_dynamic_security.so";
    let mut candidates: Vec<PathBuf> = ["/usr/lib", "/usr/lib64", "/usr/local/lib"]
        .iter()
        .map(|d| Path::new(d).join(NAME))
        .collect();
    // Debian and Ubuntu: /usr/lib/<multiarch triplet>/.
    if let Ok(entries) = std::fs::read_dir("/usr/lib") {
        for entry in entries.flatten() {
            candidates.push(entry.path().join(NAME));
        }
    }
    candidates.into_iter().find(|p| p.is_file()).ok_or_else(|| {
        format!(
            "Mosquitto's dynamic-security plugin ({NAME}, in Debian's mosquitto package) is not installed; name it with MOSQUITTO_DYNSEC_PLUGIN"
        )
    })
}

fn acl(kind: &str, topic: &str) -> Value {
    json!({ "acltype": kind, "topic": topic, "priority": 0, "allow": true })
}

/// A password as the plugin stores it: PBKDF2-SHA512 over a random 12-byte salt.
fn hashed(password: &str) -> Result<Value, String> {
    use base64::Engine;
    let mut salt = [0u8; 12];
    getrandom::fill(&mut salt).map_err(|e| format!("no randomness for a salt: {e}"))?;
    let mut hash = [0u8; 64];
    pbkdf2::pbkdf2_hmac::<sha2::Sha512>(password.as_bytes(), &salt, PASSWORD_ROUNDS, &mut hash);
    let b64 = base64::engine::general_purpose::STANDARD;
    Ok(json!({
        "password": b64.encode(hash),
        "salt": b64.encode(salt),
        "iterations": PASSWORD_ROUNDS,
    }))
}

/// The plugin's file of a new directory: the roles, the vehicles' group, the
/// administrator's login; every right not granted is refused.
fn security_file(admin_password: &str) -> Result<Value, String> {
    let mut admin = json!({
        "username": ADMIN_USER,
        "textname": "adds the fleet's logins (autoplug fleet broker add)",
        "roles": [{ "rolename": "admin" }],
    });
    if let (Some(admin), Value::Object(hash)) = (admin.as_object_mut(), hashed(admin_password)?) {
        admin.extend(hash);
    }
    Ok(json!({
        "defaultACLAccess": {
            "publishClientSend": false,
            "publishClientReceive": false,
            "subscribe": false,
            "unsubscribe": true,
        },
        "clients": [admin],
        "groups": [{
            "groupname": VEHICLES_GROUP,
            "roles": [{ "rolename": "vehicle" }],
            "clients": [],
        }],
        "roles": [
            {
                "rolename": "admin",
                "acls": [
                    acl("publishClientSend", "$CONTROL/dynamic-security/#"),
                    acl("publishClientReceive", "$CONTROL/dynamic-security/#"),
                    acl("subscribePattern", "$CONTROL/dynamic-security/#"),
                ],
            },
            {
                "rolename": "fleet",
                "acls": [
                    acl("publishClientSend", "autoplug/v1/#"),
                    acl("publishClientReceive", "autoplug/v1/#"),
                    acl("subscribePattern", "autoplug/v1/#"),
                    acl("subscribePattern", "$share/+/autoplug/v1/#"),
                ],
            },
            {
                "rolename": "vehicle",
                "acls": [
                    acl("subscribePattern", "autoplug/v1/images/#"),
                    acl("publishClientReceive", "autoplug/v1/images/#"),
                ],
            },
        ],
    }))
}

/// Writes a broker directory: `mosquitto.conf` listening for vehicles on `bind:port` and
/// for the fleet services on `fleet_bind:fleet_port`, the plugin's file with the
/// administrator's login, its password (mode 0600) and the persistence directory. Refuses
/// to overwrite a configuration that is there (it holds the logins).
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
    if files.config.exists() || files.security.exists() {
        return Err(format!(
            "{} exists already: a broker directory is written once (it holds the logins)",
            files.config.display()
        ));
    }
    let plugin = find_plugin()?;
    let plugin = plugin
        .to_str()
        .filter(|p| !p.contains(char::is_whitespace))
        .ok_or_else(|| {
            format!(
                "'{}' cannot stand in Mosquitto's configuration",
                plugin.display()
            )
        })?
        .to_string();
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
        .replace("{plugin}", &plugin)
        .replace("{fleet_bind}", fleet_bind)
        .replace("{fleet_port}", &fleet_port.to_string())
        .replace("{bind}", bind)
        .replace("{port}", &port.to_string());
    let write = |path: &Path, body: &str, mode: u32| -> Result<(), String> {
        std::fs::write(path, body)
            .map_err(|e| format!("cannot write '{}': {e}", path.display()))?;
        set_mode(path, mode)
    };
    let admin = random_password()?;
    let security = serde_json::to_string_pretty(&security_file(&admin)?)
        .map_err(|e| format!("cannot encode the logins: {e}"))?;
    write(&files.admin_password, &admin, 0o600)?;
    write(&files.security, &security, 0o600)?;
    write(&files.config, &config, 0o644)?;
    Ok(files)
}

/// The account owning `dir`, by name: a broker started as root drops to it and can still
/// read the plugin's file (mode 0600) and write its persistence. `mosquitto` (the
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
pub(crate) fn set_mode(path: &Path, mode: u32) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(|e| format!("cannot set the mode of '{}': {e}", path.display()))
}

#[cfg(not(unix))]
pub(crate) fn set_mode(_path: &Path, _mode: u32) -> Result<(), String> {
    Ok(())
}

/// A fresh random password: 24 bytes as hex (192 bits).
pub fn random_password() -> Result<String, String> {
    let mut bytes = [0u8; 24];
    getrandom::fill(&mut bytes).map_err(|e| format!("no randomness for a password: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Checks a login's name: a VIN, or [`FLEET_USER`].
fn check_user(user: &str) -> Result<Option<autoplug_vin::Vin>, String> {
    if user == FLEET_USER {
        return Ok(None);
    }
    autoplug_vin::Vin::parse(user)
        .map(Some)
        .map_err(|e| format!("'{user}' is neither a VIN ({e}) nor {FLEET_USER}"))
}

/// The commands that create `user`'s login with `password`: a vehicle's role of its own
/// (its VIN's topics) and the vehicles' group, its client id bound to the one its VIN and
/// password make ([`crate::mqtt::vehicle_client_id`]); the fleet's
/// login with the fleet's role and any client id.
fn create_commands(user: &str, password: &str) -> Result<Vec<Value>, String> {
    Ok(match check_user(user)? {
        None => vec![json!({
            "command": "createClient",
            "username": user,
            "password": password,
            "roles": [{ "rolename": "fleet" }],
        })],
        Some(vin) => {
            let own = format!("autoplug/v1/vehicles/{vin}");
            vec![
                json!({
                    "command": "createRole",
                    "rolename": format!("vehicle-{vin}"),
                    "acls": [
                        acl("publishClientSend", &format!("{own}/report/#")),
                        acl("subscribePattern", &format!("{own}/command/#")),
                        acl("publishClientReceive", &format!("{own}/command/#")),
                    ],
                }),
                json!({
                    "command": "createClient",
                    "username": user,
                    "password": password,
                    "clientid": crate::mqtt::vehicle_client_id(user, Some(password)),
                    "roles": [{ "rolename": format!("vehicle-{vin}") }],
                    "groups": [{ "groupname": VEHICLES_GROUP }],
                }),
            ]
        }
    })
}

/// The plugin's answer to one command: `None` when it was carried out.
fn answer_error(response: &Value) -> Option<String> {
    response
        .get("error")
        .and_then(Value::as_str)
        .map(str::to_string)
}

/// Logins per control message (each command is a few hundred bytes).
const LOGINS_PER_MESSAGE: usize = 50;

/// Adds logins (user, password) to the broker of `dir`, which must be running: a login
/// there already gets the new password. Vehicles by VIN, the fleet services as
/// [`FLEET_USER`].
pub fn add_logins(dir: &BrokerDir, logins: &[(String, String)]) -> Result<(), String> {
    for (user, password) in logins {
        check_user(user)?;
        if password.is_empty() {
            return Err(format!("an empty password for {user}"));
        }
    }
    let admin = std::fs::read_to_string(&dir.admin_password)
        .map_err(|e| format!("cannot read {}: {e}", dir.admin_password.display()))?;
    let (host, port) = dir.fleet_listener()?;
    let broker = Broker::at(host, port).with_login(ADMIN_USER, admin.trim());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the MQTT client: {e}"))?;
    let mut options = LinkOptions::new(format!("{ADMIN_USER}-{}", std::process::id()));
    options.subscriptions = vec![CONTROL_RESPONSE.to_string()];
    options.max_backoff = Duration::from_millis(500);
    let mut link = MqttLink::connect(runtime.handle(), &broker, options);
    link.wait_connected(Duration::from_secs(10)).map_err(|e| {
        format!(
            "{e}: is the broker running (mosquitto -c {})?",
            dir.config.display()
        )
    })?;
    let deadline = Instant::now() + Duration::from_secs(10);
    while link.status().granted.is_empty() {
        if Instant::now() > deadline || !link.status().denied.is_empty() {
            return Err(format!("{broker}: the plugin's answers are not readable"));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    for chunk in logins.chunks(LOGINS_PER_MESSAGE) {
        let mut commands = Vec::new();
        for (user, password) in chunk {
            commands.extend(create_commands(user, password)?);
        }
        let answers = control(&mut link, commands.clone())?;
        // A login there already: its role stays, its password changes.
        let mut again = Vec::new();
        for (command, answer) in commands.iter().zip(&answers) {
            match (command["command"].as_str(), answer_error(answer)) {
                (_, None) => {}
                (Some("createRole"), Some(e)) if e.contains("already exists") => {}
                (Some("createClient"), Some(e)) if e.contains("already exists") => {
                    again.push(json!({
                        "command": "setClientPassword",
                        "username": command["username"],
                        "password": command["password"],
                    }));
                    // A vehicle's client id follows its password.
                    if !command["clientid"].is_null() {
                        again.push(json!({
                            "command": "setClientId",
                            "username": command["username"],
                            "clientid": command["clientid"],
                        }));
                    }
                }
                (what, Some(e)) => {
                    return Err(format!(
                        "the broker refused {} for {}: {e}",
                        what.unwrap_or("a command"),
                        command["username"]
                            .as_str()
                            .or(command["rolename"].as_str())
                            .unwrap_or("?")
                    ))
                }
            }
        }
        if !again.is_empty() {
            for (command, answer) in again.iter().zip(control(&mut link, again.clone())?) {
                if let Some(e) = answer_error(&answer) {
                    return Err(format!(
                        "the broker refused the new password of {}: {e}",
                        command["username"]
                    ));
                }
            }
        }
    }
    link.close(Duration::from_secs(2));
    Ok(())
}

/// Adds one login (see [`add_logins`]).
pub fn add_login(dir: &BrokerDir, user: &str, password: &str) -> Result<(), String> {
    add_logins(dir, &[(user.to_string(), password.to_string())])
}

/// Sends `commands` to the plugin and waits for its answers, one per command, in order.
fn control(link: &mut MqttLink, commands: Vec<Value>) -> Result<Vec<Value>, String> {
    let n = commands.len();
    let tag = format!("autoplug-{}-{n}-{:?}", std::process::id(), Instant::now());
    let commands: Vec<Value> = commands
        .into_iter()
        .enumerate()
        .map(|(i, mut c)| {
            c["correlationData"] = json!(format!("{tag}-{i}"));
            c
        })
        .collect();
    let body = serde_json::to_vec(&json!({ "commands": commands }))
        .map_err(|e| format!("cannot encode the commands: {e}"))?;
    link.publish(CONTROL, body, false)
        .map_err(|e| e.to_string())?;
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut answers: Vec<Option<Value>> = vec![None; n];
    while answers.iter().any(Option::is_none) {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err("the broker did not answer the commands within 20 s".into());
        }
        let Some(message) = link.recv_timeout(left.min(Duration::from_millis(200))) else {
            continue;
        };
        let Ok(reply) = serde_json::from_slice::<Value>(&message.payload) else {
            continue;
        };
        for response in reply["responses"].as_array().into_iter().flatten() {
            let index = response["correlationData"]
                .as_str()
                .and_then(|c| c.strip_prefix(&format!("{tag}-")))
                .and_then(|i| i.parse::<usize>().ok());
            if let Some(slot) = index.and_then(|i| answers.get_mut(i)) {
                *slot = Some(response.clone());
            }
        }
    }
    Ok(answers.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broker_directory_is_written_once_with_every_placeholder_filled() {
        let Ok(_) = find_plugin() else {
            panic!("the dynamic-security plugin is not installed (scripts/setup-tests installs Mosquitto)");
        };
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("broker");
        let files = init(&dir, "127.0.0.1", 18830, "127.0.0.1", 18831).unwrap();
        let config = std::fs::read_to_string(&files.config).unwrap();
        assert!(!config.contains('{'), "{config}");
        assert!(config.contains("listener 18830 127.0.0.1"));
        assert!(config.contains("listener 18831 127.0.0.1"));
        assert_eq!(
            files.fleet_listener().unwrap(),
            ("127.0.0.1".to_string(), 18831)
        );
        assert!(config.contains("allow_anonymous false"));
        assert!(config.contains(&format!(
            "plugin_opt_config_file {}/dynamic-security.json",
            dir.display()
        )));
        let security: Value =
            serde_json::from_slice(&std::fs::read(&files.security).unwrap()).unwrap();
        // Nothing is granted that a role does not name.
        assert_eq!(
            security["defaultACLAccess"]["subscribe"], false,
            "{security}"
        );
        assert_eq!(security["clients"][0]["username"], ADMIN_USER);
        assert_eq!(
            std::fs::read_to_string(&files.admin_password)
                .unwrap()
                .len(),
            48
        );
        let again = init(&dir, "127.0.0.1", 18830, "127.0.0.1", 18831).unwrap_err();
        assert!(again.contains("exists already"), "{again}");
        assert!(init(&tmp.path().join("b2"), "", 1, "127.0.0.1", 2).is_err());
        assert!(init(&tmp.path().join("b3"), "127.0.0.1", 1, "127.0.0.1", 1).is_err());
        assert!(add_login(&files, "a:b", "x")
            .unwrap_err()
            .contains("neither a VIN"));
    }

    #[test]
    fn a_stored_password_is_the_plugins_pbkdf2() {
        // The plugin's own entry for the password "pw2" (made with mosquitto_ctrl).
        use base64::Engine;
        let b64 = base64::engine::general_purpose::STANDARD;
        let salt = b64.decode("KMGD5oizjp8gGz5n").unwrap();
        let mut hash = [0u8; 64];
        pbkdf2::pbkdf2_hmac::<sha2::Sha512>(b"pw2", &salt, 101, &mut hash);
        assert_eq!(
            b64.encode(hash),
            "qWMj5VnbpGFPhlopqquUrrrlpQHstXi1gWNqssjw6JHrNSueEuScqPt/gkqnKu1jJ5oOWlIngZZQyS/xLtIcGw=="
        );
        let entry = hashed("x").unwrap();
        assert_eq!(entry["iterations"], 101);
    }

    #[test]
    fn passwords_are_random() {
        let (a, b) = (random_password().unwrap(), random_password().unwrap());
        assert_eq!(a.len(), 48);
        assert_ne!(a, b);
    }
}
