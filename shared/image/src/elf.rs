//! Reading the firmware's ELF files: the loadable segments an image is made of (the image
//! tool's payloads; what a programmer writes to flash).

use object::elf;
use object::read::elf::{FileHeader, ProgramHeader};

/// The loadable segments with data of an ELF file for the STM32F446, by address (the
/// physical address: where the bytes sit in flash; .data's initial values sit in flash even
/// though the section runs in RAM).
pub fn loadable_segments(bytes: &[u8]) -> Result<Vec<(u64, &[u8])>, String> {
    if !bytes.starts_with(&elf::ELFMAG) {
        return Err("not an ELF file".into());
    }
    // e_ident[EI_CLASS], the fifth byte: 1 for 32-bit files.
    if bytes.get(4) != Some(&elf::ELFCLASS32) {
        return Err("a 64-bit ELF file: the STM32F446 runs 32-bit Arm code".into());
    }
    let header = elf::FileHeader32::<object::Endianness>::parse(bytes)
        .map_err(|e| format!("not a readable ELF file: {e}"))?;
    let endian = header
        .endian()
        .map_err(|e| format!("not a readable ELF file: {e}"))?;
    if header.e_machine(endian) != elf::EM_ARM {
        return Err(format!(
            "an ELF file for machine {} (Arm is {}): not firmware for the STM32F446",
            header.e_machine(endian),
            elf::EM_ARM
        ));
    }
    let program_headers = header
        .program_headers(endian, bytes)
        .map_err(|e| format!("unreadable program headers: {e}"))?;
    let mut segments: Vec<(u64, &[u8])> = Vec::new();
    for (index, ph) in program_headers.iter().enumerate() {
        if ph.p_type(endian) != elf::PT_LOAD || ph.p_filesz(endian) == 0 {
            continue;
        }
        let start = u64::from(ph.p_paddr(endian));
        let data = ph
            .data(endian, bytes)
            .map_err(|()| format!("segment {index} lies outside the ELF file"))?;
        segments.push((start, data));
    }
    segments.sort_by_key(|(start, _)| *start);
    Ok(segments)
}

/// A minimal executable ELF32 for Arm (or for `machine`: `object::elf::EM_ARM` is Arm) with
/// one loadable segment per `(physical address, data)` and one segment without file data in
/// RAM (.bss): for tests of the tools that read firmware files.
pub fn minimal_elf(segments: &[(u32, &[u8])], machine: u16) -> Vec<u8> {
    let count = segments.len() + 1;
    let phoff = 52u32;
    let mut data_offset = phoff + 32 * count as u32;
    let mut out = Vec::new();
    out.extend_from_slice(&[0x7F, b'E', b'L', b'F', 1, 1, 1, 0]);
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&2u16.to_le_bytes()); // ET_EXEC
    out.extend_from_slice(&machine.to_le_bytes());
    out.extend_from_slice(&1u32.to_le_bytes()); // version
    out.extend_from_slice(&0x0802_0201u32.to_le_bytes()); // entry
    out.extend_from_slice(&phoff.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes()); // shoff
    out.extend_from_slice(&0x0500_0200u32.to_le_bytes()); // flags
    out.extend_from_slice(&52u16.to_le_bytes()); // ehsize
    out.extend_from_slice(&32u16.to_le_bytes()); // phentsize
    out.extend_from_slice(&(count as u16).to_le_bytes());
    out.extend_from_slice(&40u16.to_le_bytes()); // shentsize
    out.extend_from_slice(&0u16.to_le_bytes()); // shnum
    out.extend_from_slice(&0u16.to_le_bytes()); // shstrndx
    let put_ph =
        |out: &mut Vec<u8>, offset: u32, vaddr: u32, paddr: u32, filesz: u32, memsz: u32| {
            for word in [1, offset, vaddr, paddr, filesz, memsz, 5, 4] {
                out.extend_from_slice(&u32::to_le_bytes(word));
            }
        };
    for (address, data) in segments {
        put_ph(
            &mut out,
            data_offset,
            *address,
            *address,
            data.len() as u32,
            data.len() as u32,
        );
        data_offset += data.len() as u32;
    }
    // .bss in RAM: no file data, not part of the payload.
    put_ph(&mut out, data_offset, 0x2000_0000, 0x2000_0000, 0, 0x400);
    for (_, data) in segments {
        out.extend_from_slice(data);
    }
    out
}
