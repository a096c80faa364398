//! The files around a database: creating a new one in a single step, telling an empty file
//! from a database, and the lock that tells a gateway whether another one is running.
//!
//! The database file itself is only ever opened by SQLite: closing another descriptor of it
//! would drop the POSIX locks SQLite holds on it in this process.

use std::ffi::OsString;
use std::fs::{self, File, OpenOptions, TryLockError};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// `path` with `suffix` appended to its file name (`trips.db` -> `trips.db-wal`).
pub(super) fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut name = OsString::from(path.as_os_str());
    name.push(suffix);
    PathBuf::from(name)
}

/// What is at a database's path.
pub(super) enum Found {
    /// Nothing: a new database is to be created.
    Nothing,
    /// An empty file, not one of ours (we never leave one, see [`create`]).
    EmptyFile,
    /// A directory.
    Directory,
    /// A file with something in it (or an empty one whose write-ahead log has the data):
    /// for SQLite to read.
    File,
}

/// Looks at `path` without opening it.
pub(super) fn look(path: &Path) -> io::Result<Found> {
    match fs::metadata(path) {
        Ok(m) if m.is_dir() => Ok(Found::Directory),
        Ok(m) if m.len() > 0 => Ok(Found::File),
        Ok(_) => {
            // In WAL mode the main file stays empty until the first checkpoint: its data
            // may all be in the log.
            let wal = fs::metadata(sibling(path, "-wal"))
                .map(|m| m.len())
                .unwrap_or(0);
            Ok(if wal > 0 {
                Found::File
            } else {
                Found::EmptyFile
            })
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Found::Nothing),
        Err(e) => Err(e),
    }
}

/// Creates the database `path` in a single step: `build` fills a temporary file beside it
/// and closes it (with its write-ahead log checkpointed into it), then the file is linked
/// into place. A gateway dying meanwhile leaves a temporary file, never an empty or
/// half-built `path`. If another process created `path` meanwhile, its file wins.
///
/// `build`'s error comes back as [`CreateError::Build`], one of the files as
/// [`CreateError::Files`].
pub(super) fn create<E>(
    path: &Path,
    build: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), CreateError<E>> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = sibling(path, &format!(".new-{}-{n}", std::process::id()));
    remove_database_files(&tmp);
    // Created here rather than by SQLite, so a failure says why (permission, no such
    // directory, read-only file system).
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(CreateError::Files)?;
    let result = build(&tmp).map_err(CreateError::Build).and_then(|()| {
        match fs::hard_link(&tmp, path) {
            Ok(()) => Ok(()),
            // Another process created it first: use theirs.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
            // A file system without hard links: rename (could replace a file created
            // at this very moment by another process, an accepted risk).
            Err(_) => fs::rename(&tmp, path).map_err(CreateError::Files),
        }
    });
    remove_database_files(&tmp);
    result
}

/// An error of [`create`].
pub(super) enum CreateError<E> {
    /// Of the function filling the database.
    Build(E),
    /// Of the files.
    Files(io::Error),
}

/// Removes a database file and its SQLite companions, ignoring errors (best effort).
fn remove_database_files(path: &Path) {
    for suffix in ["", "-wal", "-shm", "-journal"] {
        let _ = fs::remove_file(sibling(path, suffix));
    }
}

/// The lock beside a database (`trips.db-lock`) that every [`crate::SqliteStore`] on a file
/// holds, shared, while it is open. Whoever can take it exclusively is alone: every trip
/// still open was left by a gateway that died.
pub(super) struct WriterLock {
    file: File,
}

impl WriterLock {
    /// Takes the lock beside `path`, and says whether no other store has the database open
    /// (`true`: the caller may treat open trips as abandoned, then must call
    /// [`WriterLock::share`]). Where the file system cannot lock, says `true`: one gateway
    /// per database is then the rule.
    pub(super) fn take(path: &Path) -> io::Result<(WriterLock, bool)> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(sibling(path, "-lock"))?;
        match file.try_lock() {
            Ok(()) => Ok((WriterLock { file }, true)),
            Err(TryLockError::WouldBlock) => {
                // Others are open: share with them (waits out one that is momentarily
                // exclusive while it marks abandoned trips).
                file.lock_shared()?;
                Ok((WriterLock { file }, false))
            }
            Err(TryLockError::Error(e)) if e.kind() == io::ErrorKind::Unsupported => {
                Ok((WriterLock { file }, true))
            }
            Err(TryLockError::Error(e)) => Err(e),
        }
    }

    /// Turns the exclusive lock [`WriterLock::take`] got into a shared one, letting other
    /// stores open the database.
    pub(super) fn share(&self) -> io::Result<()> {
        match self.file.unlock() {
            Err(e) if e.kind() == io::ErrorKind::Unsupported => return Ok(()),
            other => other?,
        }
        // Between unlock and lock_shared another store may take the lock exclusively and
        // mark open trips interrupted: this one has none yet.
        self.file.lock_shared()
    }
}
