//! The ABS ECU's published parameters (node 0x0E): how the trip statistics count interventions, the wheel sensor trouble codes.

use autoplug_ecu::{Dtc, DtcSystem, FTB_SIGNAL_PLAUSIBILITY};

/// Releases of brake pressure closer together than this belong to one ABS intervention:
/// the ABS pulses a locking wheel several times a second, and one braking on a slippery
/// stretch is one intervention, however many pulses it takes.
pub const INTERVENTION_MERGE_GAP_US: u64 = 1_000_000;

/// Wheel speed sensor DTCs, FL, FR, RL, RR (the common SAE chassis codes C0035, C0040,
/// C0045, C0050 "wheel speed sensor circuit"), with failure type 0x64.
pub const WHEEL_SENSOR_DTCS: [Dtc; 4] = [
    Dtc::new(DtcSystem::C, 0x0035, FTB_SIGNAL_PLAUSIBILITY),
    Dtc::new(DtcSystem::C, 0x0040, FTB_SIGNAL_PLAUSIBILITY),
    Dtc::new(DtcSystem::C, 0x0045, FTB_SIGNAL_PLAUSIBILITY),
    Dtc::new(DtcSystem::C, 0x0050, FTB_SIGNAL_PLAUSIBILITY),
];
