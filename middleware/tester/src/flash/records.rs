//! The records of the download: which of the file's images goes to the slot the ECU
//! writes, whether the bootloader could ever start it, the address-and-length record
//! and the ECU's block length.

use autoplug_image::{ImageSet, ImageSlot, Payload, HEADER_LEN};

/// Why the file's images (one, or a release's set) could never start, if so: a machine-code
/// image whose vector table the bootloader would not start (an image without machine code
/// is for the virtual car's ECUs, which start none). Checked before anything goes to the
/// car. A file that is not an image goes as it is: the ECU says what is wrong with it.
pub(super) fn unstartable(file: &[u8]) -> Option<String> {
    let set = ImageSet::parse(file).ok()?;
    let reason = set.iter().find_map(|(image, header)| {
        let slot = header.slot()?;
        if header.payload != Payload::MachineCode {
            return None;
        }
        let table = image.get(HEADER_LEN..).unwrap_or_default();
        autoplug_image::check_startable(slot, table)
            .err()
            .map(|error| format!("the image for slot {}: {error}", slot.letter()))
    });
    reason
}

/// addressAndLengthFormatIdentifier 0x44, the slot's address and the image's length: the
/// record RequestDownload and the erase routine both carry. `None` for a length UDS cannot
/// announce (0, or 4 GiB and more).
pub(super) fn slot_and_length(slot: ImageSlot, image_len: usize) -> Option<[u8; 9]> {
    let len = u32::try_from(image_len).ok().filter(|&len| len > 0)?;
    let mut record = [0x44; 9];
    record[1..5].copy_from_slice(&slot.region().start.to_be_bytes());
    record[5..].copy_from_slice(&len.to_be_bytes());
    Some(record)
}

/// The image of `file` for `target` while the ECU runs `running`, or why there is none. A
/// file that is not a set of images goes as it is: the ECU says what is wrong with it.
pub(super) fn image_for(
    file: &[u8],
    running: ImageSlot,
    target: ImageSlot,
) -> Result<Vec<u8>, String> {
    let Ok(set) = ImageSet::parse(file) else {
        return Ok(file.to_vec());
    };
    if let Some((image, _)) = set.for_slot(target) {
        return Ok(image.to_vec());
    }
    let linked: Vec<String> = set
        .iter()
        .map(|(_, header)| match header.slot() {
            Some(slot) => format!("slot {}", slot.letter()),
            None => format!("0x{:08X}", header.load_address),
        })
        .collect();
    if set.iter().any(|(_, header)| header.slot() == Some(running)) {
        return Err(format!(
            "the ECU runs slot {} and writes the update to slot {}, but the file holds only an image linked for {}: flash a release with the slot-{} build (`autoplug image build` puts both in one file)",
            running.letter(),
            target.letter(),
            linked.join(" and "),
            target.letter()
        ));
    }
    // Linked for neither slot: the ECU refuses it with the load address it expects.
    Ok(set.first_image().to_vec())
}

/// maxNumberOfBlockLength from a RequestDownload response: `74`, the
/// lengthFormatIdentifier (its high nibble is the number of bytes that follow), the length.
pub(super) fn parse_max_block_len(response: &[u8]) -> Option<usize> {
    let [0x74, format, rest @ ..] = response else {
        return None;
    };
    let n = usize::from(format >> 4);
    if n == 0 || n > 8 || rest.len() < n {
        return None;
    }
    let value = rest[..n]
        .iter()
        .fold(0u64, |acc, &b| (acc << 8) | u64::from(b));
    usize::try_from(value).ok()
}
