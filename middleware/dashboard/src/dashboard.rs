//! `autoplug dashboard`, the main command: the virtual car in real time (or a live bus),
//! the gateway on its bus with its tester, the trips and recordings in a data folder, and
//! the web dashboard on loopback, with a write token printed at the start.
//!
//! The data folder holds `trips.db` (SQLite), `recordings/` (candump files) and `images/`
//! (the firmware library the ECUs view offers). For the virtual car, the library gets the
//! report's demonstration images at the first start: the faulty cruise control and ABS
//! software (version 1.1.0) and their fixes (1.2.0), signed with the development key.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use autoplug_can::Node;
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};

use autoplug_tester::names::ecu_name;

/// The data folder's layout.
#[derive(Clone, Debug)]
pub struct DataFolder {
    /// The folder.
    pub root: PathBuf,
}

impl DataFolder {
    /// Creates the folder and its subfolders if missing (an error names the one that failed).
    pub fn prepare(root: &Path) -> Result<Self, String> {
        let folder = Self {
            root: root.to_path_buf(),
        };
        for dir in [folder.root.clone(), folder.recordings(), folder.images()] {
            std::fs::create_dir_all(&dir)
                .map_err(|e| format!("cannot create the folder '{}': {e}", dir.display()))?;
        }
        Ok(folder)
    }

    /// The trip database.
    pub fn trips_db(&self) -> PathBuf {
        self.root.join("trips.db")
    }

    /// The recordings.
    pub fn recordings(&self) -> PathBuf {
        self.root.join("recordings")
    }

    /// The firmware library.
    pub fn images(&self) -> PathBuf {
        self.root.join("images")
    }

    /// Writes the demonstration images the library lacks, except for the ECUs in
    /// `emulated`: those run their firmware, which needs the real signed releases
    /// (scripts/firmware-demo-images), not the virtual ECUs' header-only images. Returns
    /// the names written.
    pub fn add_demo_images(&self, emulated: &[Node]) -> Result<Vec<String>, String> {
        let key = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
        let mut written = Vec::new();
        for (ecu, variant, version) in DEMO_IMAGES {
            if emulated.contains(&ecu) {
                continue;
            }
            let name = demo_image_name(ecu, variant, version);
            let path = self.images().join(&name);
            if path.exists() {
                continue;
            }
            let image = build_image(ecu, version, variant, FACTORY_PAYLOAD_LEN, &key);
            // Written under another name and renamed: never a half image in the library.
            let partial = self.images().join(format!(".{name}.partial"));
            std::fs::write(&partial, &image)
                .and_then(|()| std::fs::rename(&partial, &path))
                .map_err(|e| format!("cannot write '{}': {e}", path.display()))?;
            written.push(name);
        }
        Ok(written)
    }
}

/// What the dashboard builds for ECUs it runs as their firmware, from the checkout it runs
/// in, so that `--firmware` needs nothing prepared by hand: the firmware ELF files the car
/// loads (cargo, as `cargo build-fw -p ecu-<ecu>` does, and the bootloader in a build of its own:
/// its HAL features differ) and the signed demonstration releases of cruise and ABS for the
/// library (scripts/firmware-demo-images: the faulty build 1.1.0 and the fix 1.2.0, each
/// for both slots, the development key). Only what is missing is built.
pub struct FirmwareBuild<'a> {
    /// The checkout: `Cargo.toml` and `scripts/` of AutoPlug.
    pub root: &'a Path,
    /// The cargo to build with.
    pub cargo: PathBuf,
}

impl<'a> FirmwareBuild<'a> {
    /// The checkout at `root`, if it is one (a dashboard run elsewhere builds nothing).
    pub fn at(root: &'a Path) -> Option<Self> {
        let script = root.join("scripts/firmware-demo-images");
        (root.join("Cargo.toml").is_file() && script.is_file()).then(|| Self {
            root,
            cargo: autoplug_virtual_car::firmware::cargo(),
        })
    }

    /// Builds the ELF files of `ecus` and the bootloader that `dir` lacks; the packages
    /// built, none if nothing was missing.
    pub fn firmware(&self, ecus: &[Node], dir: &Path) -> Result<Vec<String>, String> {
        let choice = autoplug_virtual_car::firmware::FirmwareChoice {
            ecus: ecus.to_vec(),
            dir: dir.to_path_buf(),
            gdb: Vec::new(),
            hold_for_debugger: false,
        };
        choice.build_missing(self.root, &self.cargo)
    }

    /// Builds the demonstration releases of those of `ecus` that have them into `folder`'s
    /// library, when it lacks any of them; the names written.
    pub fn demo_releases(&self, ecus: &[Node], folder: &DataFolder) -> Result<Vec<String>, String> {
        let wanted: Vec<String> = DEMO_IMAGES
            .iter()
            .filter(|(ecu, ..)| ecus.contains(ecu))
            .map(|&(ecu, variant, version)| demo_image_name(ecu, variant, version))
            .collect();
        if wanted
            .iter()
            .all(|name| folder.images().join(name).exists())
        {
            return Ok(Vec::new());
        }
        // Built aside and moved in one by one: never a half release in the library.
        let building = folder.images().join(".building");
        std::fs::create_dir_all(&building)
            .map_err(|e| format!("cannot create '{}': {e}", building.display()))?;
        let script = self.root.join("scripts/firmware-demo-images");
        let result = self.run(script.as_os_str(), &[&building.to_string_lossy()]);
        let mut written = Vec::new();
        if result.is_ok() {
            for name in &wanted {
                let path = folder.images().join(name);
                if path.exists() {
                    continue;
                }
                std::fs::rename(building.join(name), &path)
                    .map_err(|e| format!("cannot move '{name}' into the library: {e}"))?;
                written.push(name.clone());
            }
        }
        let _ = std::fs::remove_dir_all(&building);
        result.map(|()| written)
    }

    /// Runs `program` with `args` in the checkout, its output on this program's standard
    /// error (cargo's progress), and says why it failed.
    fn run(&self, program: &std::ffi::OsStr, args: &[&str]) -> Result<(), String> {
        let shown = format!("{} {}", Path::new(program).display(), args.join(" "));
        let mut command = Command::new(program);
        // The releases are signed by this program, not by a build of the checkout's.
        if let Ok(me) = std::env::current_exe() {
            command.env("AUTOPLUG_BIN", me);
        }
        let status = command
            .args(args)
            .current_dir(self.root)
            .stdin(Stdio::null())
            .stdout(std::io::stderr())
            .status()
            .map_err(|e| format!("cannot run {shown}: {e}"))?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("{shown} failed ({status})"))
        }
    }
}

/// The report's demonstrations: the faulty software, then the fix (a newer version: the
/// ECUs refuse to go back).
pub const DEMO_IMAGES: [(Node, SoftwareVariant, Version); 4] = [
    (Node::Cruise, SoftwareVariant::Faulty, Version::new(1, 1, 0)),
    (
        Node::Cruise,
        SoftwareVariant::Standard,
        Version::new(1, 2, 0),
    ),
    (Node::ABS, SoftwareVariant::Faulty, Version::new(1, 1, 0)),
    (Node::ABS, SoftwareVariant::Standard, Version::new(1, 2, 0)),
];

/// `cruise-1.1.0-faulty.img`, `abs-1.2.0.img`.
pub fn demo_image_name(ecu: Node, variant: SoftwareVariant, version: Version) -> String {
    let suffix = match variant {
        SoftwareVariant::Faulty => "-faulty",
        SoftwareVariant::Standard => "",
    };
    format!("{}-{version}{suffix}.img", ecu_name(ecu))
}

/// A fresh write token: 128 random bits from the operating system, in hex.
pub fn new_token() -> Result<String, String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes).map_err(|e| format!("no randomness for the token: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// A token given by the user: 16 to 128 characters, letters, digits, `-` and `_` (it
/// travels in a URL fragment and a header).
pub fn check_token(token: &str) -> Result<(), String> {
    let ok_chars = token
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if (16..=128).contains(&token.len()) && ok_chars {
        Ok(())
    } else {
        Err("a token has 16 to 128 characters: letters, digits, - and _".into())
    }
}

/// Recordings opened for replay from the dashboard: each in a dashboard of its own (this
/// program again, `--log FILE`, on another loopback port of the same address), so the live
/// car and its page go on beside it. One at a time: opening another closes the previous.
/// The child ends with this program: it stops when its standard input closes, which happens
/// however this program ends, and it is killed when the session ends.
pub struct ReplayPages {
    listen: std::net::IpAddr,
    data: PathBuf,
    token: Option<String>,
    /// The host names this dashboard answers for besides its address.
    allowed_hosts: Vec<String>,
    child: Option<ReplayChild>,
}

/// One replay dashboard started by [`ReplayPages::open`].
struct ReplayChild {
    process: Child,
    /// The recording's file name.
    name: String,
    port: u16,
    /// It has been seen to accept connections.
    listening: bool,
}

/// A replay dashboard that runs: its recording and port, and whether it listens yet.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunningReplay<'a> {
    /// The recording's file name.
    pub file: &'a str,
    /// Its port, on the address of this dashboard.
    pub port: u16,
    /// Whether it accepts connections yet (it reads its recording first): the page opens
    /// its tab only then, rather than probing a port nobody listens on.
    pub listening: bool,
}

impl ReplayPages {
    /// Replay dashboards on `listen`'s address, with the data folder, token and allowed
    /// host names of this one (a name given with this one's port is allowed on the
    /// replay's port).
    pub fn new(
        listen: std::net::IpAddr,
        data: PathBuf,
        token: Option<String>,
        allowed_hosts: &[String],
    ) -> Self {
        let allowed_hosts = allowed_hosts
            .iter()
            .map(|host| match host.rsplit_once(':') {
                Some((name, port)) if port.parse::<u16>().is_ok() && !name.ends_with(':') => {
                    name.to_string()
                }
                _ => host.clone(),
            })
            .collect();
        Self {
            listen,
            data,
            token,
            allowed_hosts,
            child: None,
        }
    }

    /// Starts a replay dashboard on `log`; returns its port.
    pub fn open(&mut self, log: &Path) -> Result<u16, String> {
        self.close();
        let exe = std::env::current_exe().map_err(|e| format!("cannot find this program: {e}"))?;
        // A free port of the same address (asked of the OS, then handed to the child).
        let port = std::net::TcpListener::bind((self.listen, 0))
            .and_then(|l| l.local_addr())
            .map_err(|e| format!("no free port on {}: {e}", self.listen))?
            .port();
        let mut command = Command::new(exe);
        command
            .arg("dashboard")
            .arg("--log")
            .arg(log)
            .arg("--listen")
            .arg(std::net::SocketAddr::new(self.listen, port).to_string())
            .arg("--data")
            .arg(&self.data)
            .arg("--exit-with-input")
            .args(
                self.allowed_hosts
                    .iter()
                    .flat_map(|h| ["--allowed-host", h]),
            )
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        match &self.token {
            Some(token) => command.arg("--token").arg(token),
            None => command.arg("--read-only"),
        };
        let child = command
            .spawn()
            .map_err(|e| format!("cannot start the replay dashboard: {e}"))?;
        let name = log
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        self.child = Some(ReplayChild {
            process: child,
            name,
            port,
            listening: false,
        });
        Ok(port)
    }

    /// The replay dashboard running, if one runs. Until it has been seen listening, each
    /// call tries one connection to its port (loopback: refused or accepted at once).
    pub fn running(&mut self) -> Option<RunningReplay<'_>> {
        let exited = !matches!(self.child.as_mut()?.process.try_wait(), Ok(None));
        if exited {
            self.child = None;
            return None;
        }
        let child = self.child.as_mut()?;
        if !child.listening {
            let host = match self.listen {
                std::net::IpAddr::V4(a) if a.is_unspecified() => {
                    std::net::Ipv4Addr::LOCALHOST.into()
                }
                std::net::IpAddr::V6(a) if a.is_unspecified() => {
                    std::net::Ipv6Addr::LOCALHOST.into()
                }
                other => other,
            };
            let address = std::net::SocketAddr::new(host, child.port);
            child.listening = std::net::TcpStream::connect_timeout(
                &address,
                std::time::Duration::from_millis(50),
            )
            .is_ok();
        }
        Some(RunningReplay {
            file: &child.name,
            port: child.port,
            listening: child.listening,
        })
    }

    fn close(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.process.kill();
            let _ = child.process.wait();
        }
    }
}

impl Drop for ReplayPages {
    fn drop(&mut self) {
        self.close();
    }
}
