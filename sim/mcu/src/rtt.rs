//! The firmware's defmt log, read from its RTT up-buffer in the emulated SRAM as a debug
//! probe reads it (the `_SEGGER_RTT` control block, found in the ELF's symbol table) and
//! decoded with `defmt-decoder` against the same ELF, printed as probe-rs prints it.

use object::{Object, ObjectSection, ObjectSymbol};

use crate::chip::Chip;

/// The memory a probe reads the RTT buffer from and writes its read offset to: the chip
/// itself, or the MCU (which journals the write for a reverse debugger's replay).
pub trait HostMemory {
    /// Reads SRAM bytes, if all are in SRAM.
    fn sram_read(&self, address: u32, buf: &mut [u8]) -> Option<()>;
    /// Writes an SRAM word as a probe does.
    fn host_write_word(&mut self, address: u32, value: u32);
    /// The SRAM word at `address`.
    fn sram_word(&self, address: u32) -> Option<u32> {
        let mut bytes = [0u8; 4];
        self.sram_read(address, &mut bytes)?;
        Some(u32::from_le_bytes(bytes))
    }
}

impl HostMemory for Chip {
    fn sram_read(&self, address: u32, buf: &mut [u8]) -> Option<()> {
        Chip::sram_read(self, address, buf)
    }

    fn host_write_word(&mut self, address: u32, value: u32) {
        self.sram_set_word(address, value);
    }
}

impl HostMemory for crate::mcu::Mcu {
    fn sram_read(&self, address: u32, buf: &mut [u8]) -> Option<()> {
        self.chip.sram_read(address, buf)
    }

    fn host_write_word(&mut self, address: u32, value: u32) {
        self.input(crate::history::Input::HostWrite { address, value });
    }
}

/// One decoded log line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogLine {
    /// The level (`INFO`, `WARN`, …), if the frame has one.
    pub level: Option<String>,
    /// The formatted message with its timestamp, as `defmt-print` shows it.
    pub text: String,
    /// `file:line` of the log statement, when the ELF has the debug information.
    pub location: Option<String>,
}

impl core::fmt::Display for LogLine {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}", self.text)?;
        if let Some(location) = &self.location {
            write!(f, "\n└─ {location}")?;
        }
        Ok(())
    }
}

/// The log of one image (the bootloader's, or an application's).
pub struct RttLog {
    name: String,
    control_block: u32,
    /// The image's up-buffer: the bootloader and an application may put their control
    /// blocks at the same SRAM address, so the buffer the block points to tells whose it is.
    buffer: u32,
    table: defmt_decoder::Table,
    locations: defmt_decoder::Locations,
    /// Bytes read but not yet a whole rzCOBS frame (frames end with a zero byte).
    partial: Vec<u8>,
    /// Frames the decoder could not decode.
    pub malformed: u64,
}

impl RttLog {
    /// The log of the image in `elf`, if it has an RTT control block and a defmt table.
    pub fn for_elf(name: &str, elf: &[u8]) -> Result<Option<RttLog>, String> {
        let file =
            object::File::parse(elf).map_err(|e| format!("{name}: not an ELF file ({e})"))?;
        let Some(symbol) = file.symbols().find(|s| s.name() == Ok("_SEGGER_RTT")) else {
            return Ok(None);
        };
        let Some(table) = defmt_decoder::Table::parse(elf)
            .map_err(|e| format!("{name}: the defmt table cannot be read ({e})"))?
        else {
            return Ok(None);
        };
        let locations = table.get_locations(elf).unwrap_or_default();
        // The block's initial value (in .data) holds up-buffer 0's address at offset 28.
        let buffer = symbol
            .section_index()
            .and_then(|i| file.section_by_index(i).ok())
            .and_then(|section| {
                let data = section.data().ok()?;
                let at = (symbol.address() - section.address()) as usize + 28;
                Some(u32::from_le_bytes(data.get(at..at + 4)?.try_into().ok()?))
            })
            .ok_or_else(|| {
                format!("{name}: the RTT control block's initial value is not in the file")
            })?;
        Ok(Some(RttLog {
            name: name.to_string(),
            control_block: symbol.address() as u32,
            buffer,
            table,
            locations,
            partial: Vec::new(),
            malformed: 0,
        }))
    }

    /// The defmt log of the image in `elf` that has a defmt table but no RTT control block
    /// (a program that logs over semihosting, defmt-semihosting): it decodes what
    /// [`RttLog::decode`] is given and [`RttLog::poll`] finds nothing. `None` without a
    /// defmt table: the program's semihosting output is plain text.
    pub fn defmt_only(name: &str, elf: &[u8]) -> Result<Option<RttLog>, String> {
        let Some(table) = defmt_decoder::Table::parse(elf)
            .map_err(|e| format!("{name}: the defmt table cannot be read ({e})"))?
        else {
            return Ok(None);
        };
        let locations = table.get_locations(elf).unwrap_or_default();
        Ok(Some(RttLog {
            name: name.to_string(),
            control_block: 0,
            buffer: 0,
            table,
            locations,
            partial: Vec::new(),
            malformed: 0,
        }))
    }

    /// Whether a defmt frame has begun and not ended (bytes kept for the next call).
    pub fn mid_frame(&self) -> bool {
        !self.partial.is_empty()
    }

    /// The image's name, as given.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Drains up-buffer 0 (moving RdOff as a probe does) and returns the lines completed.
    pub fn poll(&mut self, chip: &mut impl HostMemory) -> Vec<LogLine> {
        let cb = self.control_block;
        if cb == 0 {
            return Vec::new();
        }
        let mut id = [0u8; 10];
        if chip.sram_read(cb, &mut id).is_none() || &id != b"SEGGER RTT" {
            return Vec::new();
        }
        let up = cb + 24;
        if chip.sram_word(up + 4) != Some(self.buffer) {
            return Vec::new();
        }
        let (Some(buffer), Some(size), Some(write), Some(read)) = (
            chip.sram_word(up + 4),
            chip.sram_word(up + 8),
            chip.sram_word(up + 12),
            chip.sram_word(up + 16),
        ) else {
            return Vec::new();
        };
        if size == 0 || write >= size || read >= size || write == read {
            return Vec::new();
        }
        let mut bytes = Vec::new();
        let mut at = read;
        while at != write {
            let end = if write > at { write } else { size };
            let mut chunk = vec![0u8; (end - at) as usize];
            if chip.sram_read(buffer + at, &mut chunk).is_none() {
                return Vec::new();
            }
            bytes.extend_from_slice(&chunk);
            at = if end == size { 0 } else { end };
        }
        chip.host_write_word(up + 16, write);
        self.decode(&bytes)
    }

    /// Decodes defmt bytes that arrived another way (semihosting output).
    pub fn decode(&mut self, bytes: &[u8]) -> Vec<LogLine> {
        self.partial.extend_from_slice(bytes);
        let Some(last_zero) = self.partial.iter().rposition(|&b| b == 0) else {
            return Vec::new();
        };
        let complete: Vec<u8> = self.partial.drain(..=last_zero).collect();
        let mut decoder = self.table.new_stream_decoder();
        decoder.received(&complete);
        let mut lines = Vec::new();
        loop {
            match decoder.decode() {
                Ok(frame) => {
                    let location = self
                        .locations
                        .get(&frame.index())
                        .map(|l| format!("{} @ {}:{}", l.module, l.file.display(), l.line));
                    lines.push(LogLine {
                        level: frame.level().map(|l| l.as_str().to_uppercase()),
                        text: frame.display(false).to_string(),
                        location,
                    });
                }
                Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
                Err(defmt_decoder::DecodeError::Malformed) => self.malformed += 1,
            }
        }
        lines
    }
}
