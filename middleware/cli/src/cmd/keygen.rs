//! `autoplug keygen`: an Ed25519 key pair for signing images.

use std::io::Write;
use std::path::Path;

use crate::cli::CliError;

/// Writes `path`.key and `path`.pub (never over existing files).
pub(crate) fn run(path: &Path, out: &mut dyn Write) -> Result<(), CliError> {
    let paths = autoplug_image_tool::keygen(path)?;
    writeln!(
        out,
        "wrote {} (secret, keep it private) and {} (public, for the ECUs)",
        paths.secret.display(),
        paths.public.display()
    )?;
    Ok(())
}
