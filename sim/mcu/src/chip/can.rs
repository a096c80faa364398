//! bxCAN, CAN1 (RM0390, section 32): the mode handshakes, three transmit mailboxes with
//! identifier or request-order priority and abort, two three-deep receive FIFOs with
//! overrun and lock, the 28 filter banks in every scale and mode with their match index,
//! the error counters, and the four interrupt lines. What is on the wire is the caller's:
//! it takes the next frame to send ([`Can::next_transmit`]), reports how it went
//! ([`Can::transmitted`]) and delivers what others sent ([`Can::receive`]).

use super::{merge, Unmodelled};

/// A frame as bxCAN holds it: standard or extended identifier, data or remote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CanFrame {
    /// The identifier (11 or 29 bits).
    pub id: u32,
    /// A 29-bit identifier.
    pub extended: bool,
    /// A remote frame.
    pub remote: bool,
    /// The data length code (0–8).
    pub dlc: u8,
    /// The data bytes (the first `dlc`).
    pub data: [u8; 8],
}

impl CanFrame {
    /// The frame in the layout of the TIxR/RIxR register (STID/EXID, IDE, RTR).
    fn id_register(&self) -> u32 {
        if self.extended {
            self.id << 3 | 0b100 | (self.remote as u32) << 1
        } else {
            self.id << 21 | (self.remote as u32) << 1
        }
    }

    fn from_registers(ir: u32, dtr: u32, dlr: u32, dhr: u32) -> Self {
        let extended = ir & 0b100 != 0;
        let id = if extended { ir >> 3 } else { ir >> 21 };
        let mut data = [0u8; 8];
        data[..4].copy_from_slice(&dlr.to_le_bytes());
        data[4..].copy_from_slice(&dhr.to_le_bytes());
        CanFrame {
            id,
            extended,
            remote: ir & 0b10 != 0,
            dlc: (dtr & 0xF).min(8) as u8,
            data,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Mailbox {
    tir: u32,
    tdtr: u32,
    tdlr: u32,
    tdhr: u32,
    /// Order of the transmit request (for TXFP).
    sequence: u64,
    /// The core cycle of the transmit request.
    requested_at: u64,
}

#[derive(Clone, Copy, Debug)]
struct Received {
    frame: CanFrame,
    filter: u32,
}

/// CAN1.
#[derive(Clone, Debug)]
pub struct Can {
    mcr: u32,
    msr: u32,
    tsr: u32,
    ier: u32,
    esr: u32,
    btr: u32,
    mailboxes: [Mailbox; 3],
    /// The mailbox on the wire now, if any.
    sending: Option<usize>,
    requests: u64,
    fifos: [Vec<Received>; 2],
    /// FULL and FOVR of each FIFO (RFxR bits 3 and 4).
    fifo_flags: [u32; 2],
    fmr: u32,
    fm1r: u32,
    fs1r: u32,
    ffa1r: u32,
    fa1r: u32,
    banks: [[u32; 2]; 28],
}

impl Default for Can {
    fn default() -> Self {
        Can {
            mcr: 0x0001_0002,
            msr: 0x0000_0C02,
            tsr: 0x1C00_0000,
            ier: 0,
            esr: 0,
            btr: 0x0123_0000,
            mailboxes: [Mailbox::default(); 3],
            sending: None,
            requests: 0,
            fifos: [Vec::new(), Vec::new()],
            fifo_flags: [0; 2],
            // CAN2SB = 14 at reset: the chip splits the banks evenly (embassy checks it).
            fmr: 0x2A1C_0E01,
            fm1r: 0,
            fs1r: 0,
            ffa1r: 0,
            fa1r: 0,
            banks: [[0; 2]; 28],
        }
    }
}

const TME0: u32 = 1 << 26;

impl Can {
    fn initialising(&self) -> bool {
        self.msr & 1 != 0
    }

    fn sleeping(&self) -> bool {
        self.msr & 2 != 0
    }

    /// Whether the controller takes part on the bus (normal mode: not in initialisation or
    /// sleep, not bus-off).
    pub fn on_bus(&self) -> bool {
        !self.initialising() && !self.sleeping() && self.esr & 0b100 == 0
    }

    /// The bit rate BTR selects with an APB1 clock of `pclk1` Hz, and whether loop-back or
    /// silent mode is on.
    pub fn bit_rate(&self, pclk1: u64) -> u64 {
        let brp = (self.btr & 0x3FF) as u64 + 1;
        let ts1 = (self.btr >> 16 & 0xF) as u64 + 1;
        let ts2 = (self.btr >> 20 & 7) as u64 + 1;
        pclk1 / (brp * (1 + ts1 + ts2))
    }

    /// Loop-back (LBKM) or silent (SILM) mode, which the model does not run.
    fn test_modes(&self) -> u32 {
        self.btr & 0xC000_0000
    }

    /// The mailbox whose frame is on the wire, as the bus last said.
    pub fn sending(&self) -> Option<usize> {
        self.sending
    }

    /// Which mailbox's frame the bus has on the wire (`autoplug_mcu::node`): an abort
    /// request waits for its transmission's end.
    pub fn set_sending(&mut self, mailbox: Option<usize>) {
        self.sending = mailbox;
    }

    /// The pending mailbox to send next (by identifier, or by request order with TXFP),
    /// marked as on the wire, and its frame.
    pub fn next_transmit(&mut self) -> Option<CanFrame> {
        if self.sending.is_some() || !self.on_bus() {
            return None;
        }
        let by_order = self.mcr & (1 << 2) != 0;
        let pending =
            (0..3).filter(|&i| self.tsr & (TME0 << i) == 0 && self.mailboxes[i].tir & 1 != 0);
        let best = if by_order {
            pending.min_by_key(|&i| self.mailboxes[i].sequence)
        } else {
            // Lower identifier first (standard ids compared as their 11 bits above the
            // extended part, as arbitration does); equal: the lower mailbox.
            pending.min_by_key(|&i| (self.mailboxes[i].tir >> 1, i))
        }?;
        self.sending = Some(best);
        let m = &self.mailboxes[best];
        Some(CanFrame::from_registers(m.tir, m.tdtr, m.tdlr, m.tdhr))
    }

    /// The frame on the wire was sent (`acked`) or not (lost arbitration or an error): the
    /// mailbox's status bits, and the transmit error counter.
    pub fn transmitted(&mut self, acked: bool, lost_arbitration: bool) {
        let Some(i) = self.sending.take() else {
            return;
        };
        let shift = 8 * i as u32;
        // An abort requested while the frame was on the wire ends with it.
        let no_retry = self.mcr & (1 << 4) != 0 || self.tsr & (0x80 << shift) != 0;
        self.tsr &= !(0x80 << shift);
        if acked {
            self.tsr = (self.tsr & !(0xF << shift)) | (0b011 << shift) | (TME0 << i);
            self.mailboxes[i].tir &= !1;
            self.set_tec(self.tec().saturating_sub(1));
            return;
        }
        if lost_arbitration {
            self.tsr |= 0b100 << shift;
            if no_retry {
                // NART: no automatic retransmission.
                self.tsr = (self.tsr & !(0b010 << shift)) | (0b001 << shift) | (TME0 << i);
                self.mailboxes[i].tir &= !1;
            }
            return;
        }
        self.tsr |= 0b1000 << shift;
        self.set_tec(self.tec() + 8);
        if no_retry {
            self.tsr = (self.tsr & !(0b010 << shift)) | (0b001 << shift) | (TME0 << i);
            self.mailboxes[i].tir &= !1;
        }
    }

    fn tec(&self) -> u32 {
        self.esr >> 16 & 0xFF
    }

    fn set_tec(&mut self, tec: u32) {
        let tec = tec.min(256);
        let rec = self.esr >> 24;
        let mut esr = (self.esr & 0x0000_FF70) | (tec.min(255)) << 16 | rec << 24;
        if tec >= 96 || rec >= 96 {
            esr |= 1;
        }
        if tec >= 128 || rec >= 128 {
            esr |= 2;
        }
        if tec > 255 {
            // Bus-off: the controller leaves the bus until software (or ABOM) recovers it.
            esr |= 4;
            if self.mcr & (1 << 6) == 0 {
                self.msr |= 1;
                self.mcr |= 1;
            }
        }
        self.esr = esr;
        if self.esr & 0b111 != 0 {
            self.msr |= 1 << 2;
        }
    }

    /// A frame another node sent: through the filters into a FIFO (if the controller is on
    /// the bus). Returns whether it was accepted.
    pub fn receive(&mut self, frame: &CanFrame) -> bool {
        if !self.on_bus() || self.test_modes() != 0 {
            return false;
        }
        let Some((fifo, filter)) = self.match_filters(frame) else {
            return false;
        };
        let queue = &mut self.fifos[fifo];
        if queue.len() == 3 {
            self.fifo_flags[fifo] |= 1 << 4;
            if self.mcr & (1 << 3) == 0 {
                // Not locked: the newest overwrites the last.
                queue[2] = Received {
                    frame: *frame,
                    filter,
                };
            }
            return true;
        }
        queue.push(Received {
            frame: *frame,
            filter,
        });
        if queue.len() == 3 {
            self.fifo_flags[fifo] |= 1 << 3;
        }
        true
    }

    /// The FIFO and filter match index for a frame (RM0390 32.7.4: 32-bit banks before
    /// 16-bit ones, list mode before mask mode, then the lower number).
    fn match_filters(&self, frame: &CanFrame) -> Option<(usize, u32)> {
        let id = frame.id_register();
        let id16 = if frame.extended {
            (frame.id >> 18) << 5 | (frame.remote as u32) << 4 | 1 << 3 | (frame.id >> 15 & 7)
        } else {
            frame.id << 5 | (frame.remote as u32) << 4
        };
        let can2sb = ((self.fmr >> 8) & 0x3F).min(28) as usize;
        // Each bank's filters in match-index order: (fifo, index, scale32, list, matches).
        let mut index = [0u32; 2];
        let mut best: Option<(u8, usize, u32)> = None;
        for bank in 0..can2sb {
            let fifo = (self.ffa1r >> bank & 1) as usize;
            let scale32 = self.fs1r >> bank & 1 != 0;
            let list = self.fm1r >> bank & 1 != 0;
            let active = self.fa1r >> bank & 1 != 0;
            let [r1, r2] = self.banks[bank];
            let count = match (scale32, list) {
                (true, false) => 1,
                (true, true) | (false, false) => 2,
                (false, true) => 4,
            };
            for k in 0..count {
                let hit = match (scale32, list) {
                    (true, false) => (id ^ r1) & r2 & !1 == 0,
                    (true, true) => (id & !1) == ((if k == 0 { r1 } else { r2 }) & !1),
                    (false, false) => {
                        let reg = if k == 0 { r1 } else { r2 };
                        (id16 ^ reg) & (reg >> 16) & 0xFFFF == 0
                    }
                    (false, true) => {
                        let reg = if k < 2 { r1 } else { r2 };
                        id16 == (reg >> (16 * (k % 2))) & 0xFFFF
                    }
                };
                let number = index[fifo];
                index[fifo] += 1;
                if active && hit {
                    let rank = (!scale32 as u8) << 1 | (!list as u8);
                    if best.is_none_or(|(r, _, n)| rank < r || (rank == r && number < n)) {
                        best = Some((rank, fifo, number));
                    }
                }
            }
        }
        best.map(|(_, fifo, number)| (fifo, number))
    }

    /// The four interrupt lines: TX, RX0, RX1, SCE.
    pub fn irqs(&self) -> [bool; 4] {
        let ier = self.ier;
        let tx = ier & 1 != 0 && self.tsr & 0x0001_0101 != 0;
        let rx = |f: usize| {
            let shift = 3 * f as u32;
            let flags = self.fifo_flags[f];
            (ier & (2 << shift) != 0 && !self.fifos[f].is_empty())
                || (ier & (4 << shift) != 0 && flags & (1 << 3) != 0)
                || (ier & (8 << shift) != 0 && flags & (1 << 4) != 0)
        };
        let sce = (self.msr & (1 << 2) != 0 && ier & (1 << 15) != 0)
            || (self.msr & (1 << 3) != 0 && ier & (1 << 16) != 0)
            || (self.msr & (1 << 4) != 0 && ier & (1 << 17) != 0);
        [tx, rx(0), rx(1), sce]
    }

    /// The mailboxes with a transmit request pending: mailbox, frame, the core cycle of the
    /// request. What a bus arbitrates among (by identifier, TXFP clear).
    pub fn requests(&self) -> impl Iterator<Item = (usize, CanFrame, u64)> + '_ {
        (0..3)
            .filter(|&i| self.tsr & (TME0 << i) == 0 && self.mailboxes[i].tir & 1 != 0)
            .map(|i| {
                let m = &self.mailboxes[i];
                (
                    i,
                    CanFrame::from_registers(m.tir, m.tdtr, m.tdlr, m.tdhr),
                    m.requested_at,
                )
            })
    }

    /// Whether transmit requests go in request order (MCR.TXFP) rather than by identifier.
    pub fn fifo_priority(&self) -> bool {
        self.mcr & (1 << 2) != 0
    }

    /// A mailbox's frame went on the wire: acknowledged (`ok`), or ended by an error, after
    /// which the bus retransmits it (`retrying`, NART clear) or gives it up.
    pub fn complete(&mut self, mailbox: usize, ok: bool, retrying: bool) {
        if mailbox >= 3 || self.tsr & (TME0 << mailbox) != 0 {
            return;
        }
        let shift = 8 * mailbox as u32;
        let abort_requested = self.tsr & (0x80 << shift) != 0;
        self.tsr &= !(0x80 << shift);
        if ok {
            self.tsr = (self.tsr & !(0xF << shift)) | (0b011 << shift) | (TME0 << mailbox);
            self.mailboxes[mailbox].tir &= !1;
        } else if abort_requested {
            // Failed with an abort requested: aborted, not retried.
            self.tsr = (self.tsr & !(0xF << shift)) | (0b1001 << shift) | (TME0 << mailbox);
            self.mailboxes[mailbox].tir &= !1;
        } else if retrying {
            self.tsr |= 0b1000 << shift;
        } else {
            self.tsr = (self.tsr & !(0xF << shift)) | (0b1001 << shift) | (TME0 << mailbox);
            self.mailboxes[mailbox].tir &= !1;
        }
        if self.sending == Some(mailbox) {
            self.sending = None;
        }
    }

    /// The error counters and bus-off state as the bus keeps them for this node: ESR's
    /// TEC, REC, EWGF, EPVF, BOFF, and the error interrupt's status (MSR.ERRI) when one
    /// of the flags rises.
    pub fn set_error_state(&mut self, tec: u16, rec: u16, bus_off: bool) {
        let old = self.esr & 0b111;
        let mut esr = (self.esr & 0x70) | (tec.min(255) as u32) << 16 | (rec.min(255) as u32) << 24;
        if tec >= 96 || rec >= 96 {
            esr |= 1;
        }
        if tec > 127 || rec > 127 {
            esr |= 2;
        }
        if bus_off {
            esr |= 4;
        }
        // ERRI: a flag went up whose interrupt is enabled (EWGIE, EPVIE, BOFIE).
        if (esr & 0b111) & !old & (self.ier >> 8) & 0b111 != 0 {
            self.msr |= 1 << 2;
        }
        self.esr = esr;
    }

    /// Reads a register.
    pub fn read(&self, offset: u32) -> Result<u32, Unmodelled> {
        Ok(match offset {
            0x000 => self.mcr,
            0x004 => self.msr,
            0x008 => {
                // LOWx: the mailbox with the lowest priority. CODE: the next free mailbox,
                // or with all three pending the lowest-priority one (RM0390 32.9.2); the
                // HAL writes its next frame where CODE points.
                let mut tsr = self.tsr & !(7 << 29) & !(3 << 24);
                let pending: Vec<usize> = (0..3).filter(|&i| self.tsr & (TME0 << i) == 0).collect();
                let low = pending
                    .iter()
                    .copied()
                    .max_by_key(|&i| (self.mailboxes[i].tir >> 1, i));
                if let Some(low) = low {
                    tsr |= 1 << (29 + low);
                }
                let code = (0..3)
                    .find(|&i| self.tsr & (TME0 << i) != 0)
                    .or(low)
                    .unwrap_or(0);
                tsr | (code as u32) << 24
            }
            0x00C | 0x010 => {
                let f = ((offset - 0x00C) / 4) as usize;
                self.fifos[f].len() as u32 | self.fifo_flags[f]
            }
            0x014 => self.ier,
            0x018 => self.esr,
            0x01C => self.btr,
            0x180..=0x1AF => {
                let m = &self.mailboxes[((offset - 0x180) / 0x10) as usize];
                [m.tir, m.tdtr, m.tdlr, m.tdhr][((offset & 0xF) / 4) as usize]
            }
            0x1B0..=0x1CF => {
                let f = ((offset - 0x1B0) / 0x10) as usize;
                let Some(head) = self.fifos[f].first() else {
                    return Ok(0);
                };
                let frame = &head.frame;
                match offset & 0xF {
                    0x0 => frame.id_register(),
                    0x4 => frame.dlc as u32 | (head.filter & 0xFF) << 8,
                    0x8 => u32::from_le_bytes(frame.data[..4].try_into().unwrap_or_default()),
                    _ => u32::from_le_bytes(frame.data[4..].try_into().unwrap_or_default()),
                }
            }
            0x200 => self.fmr,
            0x204 => self.fm1r,
            0x20C => self.fs1r,
            0x214 => self.ffa1r,
            0x21C => self.fa1r,
            0x240..=0x31C => {
                let i = ((offset - 0x240) / 4) as usize;
                self.banks[i / 2][i % 2]
            }
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes a register at core cycle `now`.
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
        now: u64,
    ) -> Result<(), Unmodelled> {
        match offset {
            0x000 => {
                let mcr = merge(self.mcr, value, mask) & 0x0001_80FF;
                if mcr & (1 << 15) != 0 {
                    *self = Can::default();
                    return Ok(());
                }
                self.mcr = mcr;
                // INRQ and SLEEP take effect at once (the bus is idle between frames in
                // the model's view of a register write).
                let inak = mcr & 1;
                let slak = if inak == 0 { mcr >> 1 & 1 } else { 0 };
                let old = self.msr;
                self.msr = (self.msr & !0b11) | inak | slak << 1;
                if old & 2 != 0 && slak == 0 {
                    self.msr |= 1 << 3; // WKUI
                }
                if old & 2 == 0 && slak != 0 {
                    self.msr |= 1 << 4; // SLAKI
                }
                if inak != 0 {
                    self.sending = None;
                }
            }
            0x004 => {
                // ERRI, WKUI, SLAKI are write-one-to-clear.
                self.msr &= !(value & mask & 0b1_1100);
            }
            0x008 => {
                let value = value & mask;
                for i in 0..3 {
                    let shift = 8 * i as u32;
                    if value & (1 << shift) != 0 {
                        self.tsr &= !(0xF << shift);
                    }
                    if value & (0x80 << shift) != 0 && self.tsr & (TME0 << i) == 0 {
                        if self.sending == Some(i) {
                            // On the wire: ABRQ stays set until the transmission ends;
                            // sent, it is TXOK, else aborted (RM0390 32.7.1). The HAL
                            // waits for ABRQ to clear, then takes TXOK as "not aborted".
                            self.tsr |= 0x80 << shift;
                        } else {
                            // Abort a pending, not yet sending, request.
                            self.mailboxes[i].tir &= !1;
                            self.tsr =
                                (self.tsr & !(0xF << shift)) | (0b001 << shift) | (TME0 << i);
                        }
                    }
                }
            }
            0x00C | 0x010 => {
                let f = ((offset - 0x00C) / 4) as usize;
                let value = value & mask;
                // FULL and FOVR clear by writing 1; RFOM releases the head.
                self.fifo_flags[f] &= !(value & 0b1_1000);
                if value & (1 << 5) != 0 && !self.fifos[f].is_empty() {
                    self.fifos[f].remove(0);
                    self.fifo_flags[f] &= !(1 << 3);
                }
            }
            0x014 => self.ier = merge(self.ier, value, mask) & 0x0003_8F7F,
            0x018 => self.esr = (self.esr & !0x70) | (merge(self.esr, value, mask) & 0x70),
            0x01C => {
                if !self.initialising() {
                    return Ok(());
                }
                self.btr = merge(self.btr, value, mask) & 0xC37F_03FF;
                if self.test_modes() != 0 {
                    return Err(Unmodelled::feature(
                        "loop-back or silent mode (BTR.LBKM/SILM)",
                    ));
                }
            }
            0x180..=0x1AF => {
                let i = ((offset - 0x180) / 0x10) as usize;
                if self.tsr & (TME0 << i) == 0 {
                    // A mailbox with a pending request is read-only.
                    return Ok(());
                }
                let m = &mut self.mailboxes[i];
                match offset & 0xF {
                    0x0 => {
                        m.tir = merge(m.tir, value, mask);
                        if m.tir & 1 != 0 {
                            self.requests += 1;
                            m.sequence = self.requests;
                            m.requested_at = now;
                            self.tsr &= !(TME0 << i);
                        }
                    }
                    0x4 => m.tdtr = merge(m.tdtr, value, mask) & 0xFFFF_010F,
                    0x8 => m.tdlr = merge(m.tdlr, value, mask),
                    _ => m.tdhr = merge(m.tdhr, value, mask),
                }
            }
            0x1B0..=0x1CF => {}
            0x200 => self.fmr = merge(self.fmr, value, mask) & 0x0000_3F01 | 0x2A1C_0000,
            // Mode, scale and FIFO assignment are writable only in FINIT; the chip ignores
            // other writes.
            0x204 | 0x20C | 0x214 if self.fmr & 1 == 0 => {}
            0x204 => self.fm1r = merge(self.fm1r, value, mask) & 0x0FFF_FFFF,
            0x20C => self.fs1r = merge(self.fs1r, value, mask) & 0x0FFF_FFFF,
            0x214 => self.ffa1r = merge(self.ffa1r, value, mask) & 0x0FFF_FFFF,
            0x21C => self.fa1r = merge(self.fa1r, value, mask) & 0x0FFF_FFFF,
            0x240..=0x31C => {
                let i = ((offset - 0x240) / 4) as usize;
                let bank = i / 2;
                // A bank's registers are writable while it is inactive or in FINIT.
                if self.fa1r >> bank & 1 == 0 || self.fmr & 1 != 0 {
                    self.banks[bank][i % 2] = merge(self.banks[bank][i % 2], value, mask);
                }
            }
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u32) -> CanFrame {
        CanFrame {
            id,
            extended: false,
            remote: false,
            dlc: 2,
            data: [1, 2, 0, 0, 0, 0, 0, 0],
        }
    }

    fn on_bus() -> Can {
        let mut can = Can::default();
        can.write(0x000, 1, u32::MAX, 0).unwrap(); // INRQ, leave sleep
        can.write(0x000, 0, u32::MAX, 0).unwrap(); // normal mode
        assert!(can.on_bus());
        can
    }

    #[test]
    fn sixteen_bit_list_filters_accept_only_their_ids_with_the_match_index() {
        let mut can = on_bus();
        can.write(0x200, 0x0E01, u32::MAX, 0).unwrap(); // FINIT, CAN2SB kept at 14
        can.write(0x204, 0b10, u32::MAX, 0).unwrap(); // bank 1 list mode (bank 0 mask)
        can.write(0x214, 0, u32::MAX, 0).unwrap();
        // Bank 0, 16-bit mask: id 0x7FF exact (both halves); bank 1 list: 0x100, 0x101, 0x102, 0x103.
        can.write(0x240, 0xFFE0_FFE0, u32::MAX, 0).unwrap();
        can.write(0x244, 0xFFE0_FFE0, u32::MAX, 0).unwrap();
        can.write(0x248, (0x101 << 5) << 16 | 0x100 << 5, u32::MAX, 0)
            .unwrap();
        can.write(0x24C, (0x103 << 5) << 16 | 0x102 << 5, u32::MAX, 0)
            .unwrap();
        can.write(0x21C, 0b11, u32::MAX, 0).unwrap();
        can.write(0x200, 0x0E00, u32::MAX, 0).unwrap();
        assert!(can.receive(&frame(0x102)));
        assert!(!can.receive(&frame(0x104)));
        assert!(can.receive(&frame(0x7FF)));
        assert_eq!(can.read(0x00C).unwrap() & 3, 2);
        // List filters rank before mask filters; the index counts every filter of FIFO 0:
        // bank 0 has two (0, 1), bank 1 four (2..=5): 0x102 is index 4.
        assert_eq!(can.read(0x1B4).unwrap() >> 8 & 0xFF, 4);
        assert_eq!(can.read(0x1B0).unwrap() >> 21, 0x102);
        can.write(0x00C, 1 << 5, u32::MAX, 0).unwrap();
        assert_eq!(can.read(0x1B0).unwrap() >> 21, 0x7FF);
    }

    #[test]
    fn the_lowest_identifier_goes_first_and_a_pending_request_can_be_aborted() {
        let mut can = on_bus();
        for (mailbox, id) in [(0u32, 0x300), (1, 0x100), (2, 0x200)] {
            let base = 0x180 + 0x10 * mailbox;
            can.write(base + 4, 2, u32::MAX, 0).unwrap();
            can.write(base, id << 21 | 1, u32::MAX, 0).unwrap();
        }
        assert_eq!(can.next_transmit().map(|f| f.id), Some(0x100));
        // Abort mailbox 0 (pending) and mailbox 1 (on the wire: not aborted).
        can.write(0x008, 0x80 | 0x8000, u32::MAX, 0).unwrap();
        let tsr = can.read(0x008).unwrap();
        assert_ne!(tsr & (1 << 26), 0, "mailbox 0 empty after the abort");
        assert_eq!(tsr & 0b10, 0, "aborted: no TXOK");
        assert_eq!(tsr & (1 << 27), 0, "mailbox 1 still busy");
        can.transmitted(true, false);
        assert_eq!(
            can.read(0x008).unwrap() >> 8 & 0b11,
            0b11,
            "RQCP1 and TXOK1"
        );
        assert_eq!(can.next_transmit().map(|f| f.id), Some(0x200));
    }

    #[test]
    fn an_abort_of_the_frame_on_the_wire_waits_for_its_end() {
        // The HAL aborts the lowest-priority mailbox to make room and takes its frame
        // back only if ABRQ cleared without TXOK: a frame on the wire that then goes out
        // must read as sent, or the firmware sends it twice.
        let mut can = on_bus();
        can.write(0x184, 1, u32::MAX, 0).unwrap();
        can.write(0x180, 0x78E << 21 | 1, u32::MAX, 0).unwrap();
        can.set_sending(Some(0));
        can.write(0x008, 0x80, u32::MAX, 0).unwrap();
        let tsr = can.read(0x008).unwrap();
        assert_ne!(tsr & 0x80, 0, "ABRQ0 set while the frame is on the wire");
        assert_eq!(tsr & (1 << 26), 0, "mailbox 0 still busy");
        can.complete(0, true, false);
        let tsr = can.read(0x008).unwrap();
        assert_eq!(
            tsr & 0x83,
            0b11,
            "ABRQ0 clear, RQCP0 and TXOK0: it was sent"
        );
        // On the wire and then lost: aborted, not retried.
        can.write(0x180, 0x78E << 21 | 1, u32::MAX, 0).unwrap();
        can.set_sending(Some(0));
        can.write(0x008, 0x80, u32::MAX, 0).unwrap();
        can.complete(0, false, true);
        let tsr = can.read(0x008).unwrap();
        assert_eq!(
            tsr & 0x83,
            0b01,
            "ABRQ0 clear, RQCP0 without TXOK0: aborted"
        );
        assert_eq!(can.requests().count(), 0, "not retried");
    }

    #[test]
    fn tsr_code_points_at_the_next_free_mailbox_then_at_the_lowest_priority() {
        // The HAL writes each frame into the mailbox CODE names: frames queued back to
        // back must each get their own (a CODE stuck at a busy mailbox loses them, as a
        // pending mailbox ignores writes).
        let mut can = on_bus();
        let code = |can: &mut Can| can.read(0x008).unwrap() >> 24 & 3;
        for (id, expected_code) in [(0x021, 0), (0x020, 1), (0x022, 2)] {
            let mailbox = code(&mut can);
            assert_eq!(mailbox, expected_code);
            let base = 0x180 + 0x10 * mailbox;
            can.write(base + 4, 1, u32::MAX, 0).unwrap();
            can.write(base, id << 21 | 1, u32::MAX, 0).unwrap();
        }
        let mut pending: Vec<u32> = can.requests().map(|(_, f, _)| f.id).collect();
        pending.sort_unstable();
        assert_eq!(pending, [0x020, 0x021, 0x022], "all three pending");
        // All pending: CODE (and LOW) name the lowest priority, 0x022 in mailbox 2.
        let tsr = can.read(0x008).unwrap();
        assert_eq!((tsr >> 24 & 3, tsr >> 29), (2, 0b100));
        can.complete(1, true, false);
        assert_eq!(code(&mut can), 1, "mailbox 1 free again");
    }

    #[test]
    fn a_bus_reports_completions_and_error_counters_into_the_mailboxes_and_esr() {
        let mut can = on_bus();
        can.write(0x014, 1 << 15 | 1 << 10, u32::MAX, 0).unwrap(); // ERRIE, BOFIE
        can.write(0x184, 1, u32::MAX, 0).unwrap();
        can.write(0x180, 0x123 << 21 | 1, u32::MAX, 500).unwrap();
        let requests: Vec<_> = can.requests().collect();
        assert_eq!(requests.len(), 1);
        assert_eq!(
            (requests[0].0, requests[0].1.id, requests[0].2),
            (0, 0x123, 500)
        );
        can.complete(0, false, true);
        assert_ne!(can.read(0x008).unwrap() & 0b1000, 0, "TERR0");
        assert_eq!(can.requests().count(), 1, "still pending: the bus retries");
        can.complete(0, true, false);
        assert_eq!(can.read(0x008).unwrap() & 0b11, 0b11, "RQCP0, TXOK0");
        assert_eq!(can.requests().count(), 0);
        can.set_error_state(256, 3, true);
        let esr = can.read(0x018).unwrap();
        assert_eq!(esr & 0b111, 0b111, "EWGF, EPVF, BOFF");
        assert_eq!((esr >> 16 & 0xFF, esr >> 24), (255, 3));
        assert!(can.irqs()[3], "the SCE line: bus-off with BOFIE and ERRIE");
    }

    #[test]
    fn the_reset_value_of_fmr_gives_can2_the_upper_half() {
        assert_eq!(Can::default().read(0x200).unwrap(), 0x2A1C_0E01);
    }
}
