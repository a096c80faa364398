//! The two engines every fleet test runs on: a fresh SQLite file, and a schema of its own on
//! the PostgreSQL server at `AUTOPLUG_TEST_POSTGRES` (default: the local server, database
//! `test`). The real server, never a stand-in: a test fails, naming the address, when it is
//! not there (`scripts/setup-tests` installs and starts one).

#![allow(dead_code)]

use autoplug_fleet::FleetStore;

#[allow(unused_imports)]
pub use autoplug_fleet::testing::{broker_url, postgres_url, PgSchema};

/// A fresh store on one engine, and what keeps it alive.
pub enum Engine {
    Sqlite(tempfile::TempDir),
    Postgres(PgSchema),
}

impl Engine {
    pub fn label(&self) -> &'static str {
        match self {
            Engine::Sqlite(_) => "SQLite",
            Engine::Postgres(_) => "PostgreSQL",
        }
    }

    /// The address `FleetStore::open` takes.
    pub fn address(&self) -> String {
        match self {
            Engine::Sqlite(dir) => dir.path().join("fleet.db").display().to_string(),
            Engine::Postgres(schema) => schema.url.clone(),
        }
    }

    pub fn open(&self) -> FleetStore {
        FleetStore::open(&self.address()).unwrap_or_else(|e| panic!("{}: {e}", self.label()))
    }
}

/// Both engines, fresh.
pub fn engines() -> [Engine; 2] {
    [
        Engine::Sqlite(tempfile::tempdir().unwrap()),
        Engine::Postgres(PgSchema::new()),
    ]
}

/// A Mosquitto of the test's own, run from the project's broker configuration (logins,
/// ACL, persistence) on a free port; killed when dropped. The binary: `$MOSQUITTO`, else
/// `/usr/sbin/mosquitto`, else `mosquitto` on the PATH.
pub struct PrivateBroker {
    pub dir: tempfile::TempDir,
    pub files: autoplug_fleet::broker::BrokerDir,
    pub port: u16,
    /// The fleet services' listener.
    pub fleet_port: u16,
    child: std::process::Child,
}

impl PrivateBroker {
    pub fn start() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let free = || {
            std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        };
        let (port, fleet_port) = (free(), free());
        let files = autoplug_fleet::broker::init(
            &dir.path().join("broker"),
            "127.0.0.1",
            port,
            "127.0.0.1",
            fleet_port,
        )
        .unwrap();
        let child = Self::spawn(&files);
        let broker = Self {
            dir,
            files,
            port,
            fleet_port,
            child,
        };
        broker.wait_listening();
        broker
    }

    fn spawn(files: &autoplug_fleet::broker::BrokerDir) -> std::process::Child {
        let binary = std::env::var("MOSQUITTO").unwrap_or_else(|_| {
            if std::path::Path::new("/usr/sbin/mosquitto").exists() {
                "/usr/sbin/mosquitto".into()
            } else {
                "mosquitto".into()
            }
        });
        std::process::Command::new(&binary)
            .arg("-c")
            .arg(&files.config)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("cannot run {binary} (scripts/setup-tests installs Mosquitto): {e}")
            })
    }

    fn wait_listening(&self) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        for port in [self.port, self.fleet_port] {
            while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
                assert!(
                    std::time::Instant::now() < deadline,
                    "mosquitto did not listen on {port}"
                );
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        }
    }

    /// Adds a login and makes the running broker read the password file again.
    pub fn add_login(&self, user: &str, password: &str) {
        autoplug_fleet::broker::add_login(&self.files, user, password).unwrap();
        // SIGHUP: Mosquitto reloads its password and ACL files.
        let status = std::process::Command::new("kill")
            .args(["-HUP", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        std::thread::sleep(std::time::Duration::from_millis(200));
    }

    /// The address for `user` with `password`: the fleet services' listener for the
    /// fleet's login, the vehicles' for any other.
    pub fn url(&self, user: &str, password: &str) -> autoplug_fleet::mqtt::Broker {
        let port = if user == autoplug_fleet::broker::FLEET_USER {
            self.fleet_port
        } else {
            self.port
        };
        self.url_at(port, user, password)
    }

    /// The address of the listener on `port` for `user` with `password`.
    pub fn url_at(&self, port: u16, user: &str, password: &str) -> autoplug_fleet::mqtt::Broker {
        format!("mqtt://{user}:{password}@127.0.0.1:{port}")
            .parse()
            .unwrap()
    }

    /// Stops the broker as a restart would (SIGTERM: it saves its persistence) and starts it
    /// again from the same directory.
    pub fn restart(&mut self) {
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
        self.child = Self::spawn(&self.files);
        self.wait_listening();
    }
}

impl Drop for PrivateBroker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A runtime for the tests' MQTT connections.
pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}
