//! The AutoPlug CAN catalogue (spec section 3), generated at build time from
//! `autoplug.dbc`, the one place a message identifier, byte position or scale is written.
//!
//! `no_std` and allocation-free, so the firmware, the vehicle simulation and the host tools
//! all use the same code. Each message is a struct of physical values:
//!
//! - `encode()` rounds and clamps every value into its valid range (a sender never puts an
//!   out-of-range value on the bus);
//! - `decode()` rejects a frame of the wrong length or with any invalid signal;
//! - `update_from()` keeps the last good value of each invalid signal, as receivers must.
//!
//! ```
//! use autoplug_can::{DecodeError, EngineMode, EngineMsg, Message, SteeringMsg};
//!
//! let frame = EngineMsg { engine_rpm: 3000.0, fuel_level: 48.0, engine_mode: EngineMode::Sport, fuel_used: 1234.0 }.encode();
//! assert_eq!(frame, [85, 192, 0, 0xD2, 0x04]);
//! let Ok(Message::EngineMsg(engine)) = Message::decode(EngineMsg::ID, &frame) else { panic!() };
//! assert_eq!(engine.fuel_level, 48.0);
//!
//! let mut steering = SteeringMsg::default(); // straight ahead until the first frame
//! assert!(matches!(steering.update_from(&[5]), Err(DecodeError::OutOfRange { raw: 5, .. })));
//! assert_eq!(steering.steering_angle, 0.0); // the invalid value was not taken
//! ```
//!
//! Fuel level is encoded at 0.25 L per bit (litres × 4, 0..63.75 L), so the EVO VI's 48 L
//! tank fits one byte with headroom (spec note A).
#![no_std]
#![deny(missing_docs)]

pub mod codec;
mod ecu_names;
mod frame;
mod spec;

pub use autoplug_scaling::LinearScale;
pub use codec::{DecodeError, SignalError};
pub use ecu_names::{ecu_name, parse_ecu, ECUS, ECU_NAME_LIST};
pub use frame::{Frame, FrameError};
pub use spec::{CanMessage, MessageSpec, SignalKind, SignalSpec};

/// The DBC file this catalogue was generated from, as it is: what the dashboard offers for
/// download, so a user's own tools (cantools, SavvyCAN, CANalyzer) decode the same bus.
pub const DBC_FILE: &str = include_str!("../autoplug.dbc");

mod catalogue {
    use crate::codec::{self, DecodeError, SignalError};
    use crate::spec::{CanMessage, MessageSpec, SignalKind, SignalSpec};
    use crate::Frame;
    use autoplug_scaling::{round_half_away_from_zero, LinearScale};
    include!(concat!(env!("OUT_DIR"), "/catalogue.rs"));
}

pub use catalogue::*;

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
