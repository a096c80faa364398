//! The engine ECU's published parameters (node 0x03): the range of its fuel-flow input.

/// Highest fuel flow the ECU's input reads, L/h (the EVO VI burns about 90 L/h at full
/// power).
pub const FUEL_FLOW_MAX_L_PER_H: f32 = 150.0;
