//! OBD-II mode 01 (SAE J1979 / ISO 15031-5) on the functional identifier: the ECUs that own
//! a value answer with it; the others stay silent, as OBD-II wants.

use crate::server::Backend;

/// Mode 01: show current data.
pub const MODE_CURRENT_DATA: u8 = 0x01;
/// PIDs 0x00, 0x20, 0x40...: which of the next 32 PIDs are supported.
const SUPPORT_STEP: u8 = 0x20;

/// Answers a mode 01 request (`01 pid [pid...]`, up to six PIDs) into `out` with the
/// values this ECU has, or `None` when it has none of them (or the request is not mode
/// 01). A response that would not fit one ISO-TP single frame (7 bytes) stops at the
/// last PID that fits: OBD-II scan tools ask for one PID at a time anyway.
pub fn answer_mode01(request: &[u8], backend: &mut impl Backend, out: &mut [u8]) -> Option<usize> {
    let (&mode, pids) = request.split_first()?;
    if mode != MODE_CURRENT_DATA || pids.is_empty() || pids.len() > 6 {
        return None;
    }
    out[0] = MODE_CURRENT_DATA + 0x40;
    let mut len = 1;
    for &pid in pids {
        let mut value = [0u8; 4];
        let n = if pid % SUPPORT_STEP == 0 {
            match support_bitmap(backend.obd_pids(), pid) {
                Some(bitmap) => {
                    value = bitmap.to_be_bytes();
                    4
                }
                None => continue,
            }
        } else if backend.obd_pids().contains(&pid) {
            match backend.obd_read(pid, &mut value) {
                Some(n) => n,
                None => continue,
            }
        } else {
            continue;
        };
        if len + 1 + n > 7 {
            break;
        }
        out[len] = pid;
        out[len + 1..len + 1 + n].copy_from_slice(&value[..n]);
        len += 1 + n;
    }
    (len > 1).then_some(len)
}

/// The support bitmap at `base` (0x00, 0x20, ...): bit 31 is PID base + 1, bit 0 is
/// base + 32, which also says the next bitmap exists. `None` when this ECU has no PID at or
/// beyond `base` (only the ECU with PIDs there answers, except at 0x00, which every ECU
/// with any PID answers).
fn support_bitmap(pids: &[u8], base: u8) -> Option<u32> {
    if pids.is_empty() || (base != 0 && !pids.iter().any(|&p| p > base)) {
        return None;
    }
    let mut bitmap = 0u32;
    for &pid in pids {
        if pid > base && u16::from(pid) <= u16::from(base) + 32 {
            bitmap |= 1 << (32 - (pid - base));
        }
    }
    if pids.iter().any(|&p| u16::from(p) > u16::from(base) + 32) {
        bitmap |= 1;
    }
    Some(bitmap)
}

#[cfg(test)]
mod tests {
    use super::support_bitmap;

    #[test]
    fn bitmaps_say_which_pids_follow() {
        // Engine: RPM (0x0C) and fuel level (0x2F).
        let engine = [0x0C, 0x2F];
        assert_eq!(support_bitmap(&engine, 0x00), Some(0x0010_0001));
        assert_eq!(support_bitmap(&engine, 0x20), Some(0x0002_0000));
        assert_eq!(support_bitmap(&engine, 0x40), None);
        // Cruise: vehicle speed (0x0D) only.
        assert_eq!(support_bitmap(&[0x0D], 0x00), Some(0x0008_0000));
        assert_eq!(support_bitmap(&[0x0D], 0x20), None);
        assert_eq!(support_bitmap(&[], 0x00), None);
    }
}
