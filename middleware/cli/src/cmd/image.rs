//! `autoplug image build` and `autoplug image inspect`: signed images, written and read.

use std::io::Write;
use std::path::Path;

use autoplug_image_tool::{BuildOptions, ImageToolError, PayloadKind};

use crate::cli::{BuildArgs, CliError};

/// Builds and signs an image (or a release for both slots) and describes what it wrote.
pub(crate) fn build(args: BuildArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let BuildArgs {
        ecu,
        version,
        variant,
        part_number,
        build_id,
        payload,
        slot,
        key,
        out: image,
    } = args;
    let options = BuildOptions {
        ecu,
        version,
        variant: variant.into(),
        part_number,
        build_id,
        payloads: payload,
        slot: slot.map(Into::into),
        key,
        out: image,
    };
    let built = autoplug_image_tool::build_image(&options)?;
    writeln!(
        out,
        "wrote {} ({} bytes, {} image(s))",
        options.out.display(),
        built.image_len,
        built.images.len()
    )?;
    for (header, kind) in &built.images {
        let kind = match kind {
            PayloadKind::Raw => "raw binary".to_string(),
            PayloadKind::Elf { segments } => {
                format!("ELF, {segments} loadable segment(s)")
            }
        };
        let slot = header.slot().map_or('?', |slot| slot.letter());
        writeln!(
            out,
            "slot {slot}: payload {} bytes from {kind}\n{header}",
            header.payload_len,
        )?;
    }
    Ok(())
}

/// Shows every image of the file; an image with problems is an error (after the listing).
pub(crate) fn inspect(
    file: &Path,
    key: Option<&Path>,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let inspections = autoplug_image_tool::inspect_file(file, key)?;
    writeln!(out, "File:           {}", file.display())?;
    let mut problems = Vec::new();
    for (index, inspection) in inspections.iter().enumerate() {
        if inspections.len() > 1 {
            writeln!(out, "--- image {} of {}", index + 1, inspections.len())?;
        }
        writeln!(out, "{inspection}")?;
        problems.extend(inspection.problems());
    }
    if !problems.is_empty() {
        return Err(ImageToolError::Corrupted {
            path: file.to_path_buf(),
            problems,
        }
        .into());
    }
    Ok(())
}
