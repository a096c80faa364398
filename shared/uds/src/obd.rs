//! OBD-II mode 01 (SAE J1979 / ISO 15031-5) on the functional identifier: the ECUs that own
//! a value answer with it; the others stay silent, as OBD-II wants.

use autoplug_can::Node;

use crate::server::Backend;

/// Tank capacity for PID 0x2F (fuel level in percent of the tank): the EVO VI's 48 L.
pub const FUEL_TANK_L: f32 = 48.0;

/// The values an ECU has for mode 01, as it measured them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ObdValues {
    /// Engine speed, rpm.
    pub engine_rpm: Option<f32>,
    /// Fuel in the tank, litres.
    pub fuel_l: Option<f32>,
    /// Vehicle speed, km/h.
    pub speed_kmh: Option<f32>,
}

/// The mode 01 PIDs each ECU owns: the engine its speed (0x0C) and fuel level (0x2F), the
/// cruise control ECU (which measures it) the vehicle speed (0x0D).
pub fn pids_of(node: Node) -> &'static [u8] {
    match node {
        Node::Engine => &[0x0C, 0x2F],
        Node::Cruise => &[0x0D],
        _ => &[],
    }
}

/// The data bytes of `pid` (SAE J1979 scaling) into `out`; `None` when the value is
/// unknown or the PID is not one of these.
pub fn encode(pid: u8, values: &ObdValues, out: &mut [u8]) -> Option<usize> {
    match pid {
        // Engine speed: (256 A + B) / 4 rpm.
        0x0C => {
            let quarter_rpm = (values.engine_rpm? * 4.0).clamp(0.0, 65_535.0) as u16;
            out.get_mut(..2)?
                .copy_from_slice(&quarter_rpm.to_be_bytes());
            Some(2)
        }
        // Vehicle speed: A km/h.
        0x0D => {
            *out.first_mut()? = (values.speed_kmh?.clamp(0.0, 255.0) + 0.5) as u8;
            Some(1)
        }
        // Fuel tank level input: 100 A / 255 %.
        0x2F => {
            let fraction = values.fuel_l? / FUEL_TANK_L;
            *out.first_mut()? = (fraction.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            Some(1)
        }
        _ => None,
    }
}

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
    use super::*;

    #[test]
    fn values_are_scaled_as_sae_j1979_says() {
        let values = ObdValues {
            engine_rpm: Some(3000.0),
            fuel_l: Some(24.0),
            speed_kmh: Some(87.4),
        };
        let mut out = [0u8; 4];
        assert_eq!(encode(0x0C, &values, &mut out), Some(2));
        assert_eq!(out[..2], [0x2E, 0xE0]); // 12000 / 4 = 3000 rpm
        assert_eq!(encode(0x2F, &values, &mut out), Some(1));
        assert_eq!(out[0], 128); // half the tank
        assert_eq!(encode(0x0D, &values, &mut out), Some(1));
        assert_eq!(out[0], 87);
        assert_eq!(encode(0x0D, &ObdValues::default(), &mut out), None);
        assert_eq!(encode(0x05, &values, &mut out), None);
    }

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
