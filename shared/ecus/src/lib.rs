//! The car's ECUs, one entry each: the one list the virtual car, the host and on-target
//! tests and the pin-map check go by (the scripts and CI take theirs from the `ecu-*`
//! folders, `scripts/ecus`).
//!
//! An ECU is its crate `ecu-NAME` (its logic as a `no_std` state machine, its pins, its
//! firmware) and a line here: in [`for_each_ecu!`] and in this crate's `Cargo.toml`. Each
//! crate publishes what the tools read from it: `STEP_PERIOD_US`, `PART_NUMBER` and
//! `pins::SIGNALS`.
//!
//! Why a macro beside the table: the ECUs' logic types differ, so code that holds one of
//! each (the virtual car's slots, an on-target suite per ECU) is written once as a macro
//! over this list rather than nine times by hand.
#![no_std]
#![forbid(unsafe_code)]

pub use autoplug_can::Node;
pub use autoplug_ecu::pins::Signal;

/// Calls the macro `$callback` with every ECU of the car, in the order the virtual car
/// starts them (their control steps' phases follow it), as
/// `(Node variant, short name, crate, logic type)`; the short name is this crate's
/// re-export of the ECU's crate (`autoplug_ecus::cruise::CruiseEcu`).
#[macro_export]
macro_rules! for_each_ecu {
    ($callback:ident) => {
        $callback! {
            (Pedals, pedals, ecu_pedals, PedalsEcu),
            (Steering, steering, ecu_steering, SteeringEcu),
            (Console, console, ecu_console, ConsoleEcu),
            (Engine, engine, ecu_engine, EngineEcu),
            (Transmission, trans, ecu_trans, TransEcu),
            (Cabin, cabin, ecu_cabin, CabinEcu),
            (Differential, diff, ecu_diff, DiffEcu),
            (Cruise, cruise, ecu_cruise, CruiseEcu),
            (ABS, abs, ecu_abs, AbsEcu),
        }
    };
}

/// What the tools know of an ECU, read from its crate.
#[derive(Clone, Copy, Debug)]
pub struct EcuEntry {
    /// Its node in the DBC.
    pub node: Node,
    /// The short name of its crate and firmware: `ecu-{name}`, `{name}-fw`.
    pub name: &'static str,
    /// Its control step period, µs.
    pub step_period_us: u64,
    /// Its board's signals (the CAN pins aside).
    pub signals: &'static [Signal],
    /// The part number of its software (UDS 0xF187).
    pub part_number: &'static str,
}

macro_rules! registry {
    ($(($node:ident, $name:ident, $krate:ident, $logic:ident)),* $(,)?) => {
        $(pub use $krate as $name;)*

        /// Every ECU of the car, in the order of [`for_each_ecu!`].
        pub const ECUS: &[EcuEntry] = &[$(EcuEntry {
            node: Node::$node,
            name: stringify!($name),
            step_period_us: $krate::STEP_PERIOD_US,
            signals: $krate::pins::SIGNALS,
            part_number: $krate::PART_NUMBER,
        }),*];
    };
}
for_each_ecu!(registry);

/// The entry of the ECU at `node`; `None` for a node that is no ECU (the gateway).
pub fn ecu(node: Node) -> Option<&'static EcuEntry> {
    ECUS.iter().find(|e| e.node == node)
}

/// The short name of the ECU's crate and firmware (`trans` for `ecu-trans` and `trans-fw`);
/// the node's own name in lower case for a node that is no ECU.
pub fn firmware_name(node: Node) -> &'static str {
    ecu(node).map_or_else(|| node.short_name(), |e| e.name)
}

/// The entry of the ECU whose crate is `ecu-{name}`.
pub fn by_name(name: &str) -> Option<&'static EcuEntry> {
    ECUS.iter().find(|e| e.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_ecu_of_the_dbc_is_registered_once() {
        assert_eq!(ECUS.len(), autoplug_can::ECUS.len());
        for node in autoplug_can::ECUS {
            assert_eq!(
                ECUS.iter().filter(|e| e.node == node).count(),
                1,
                "{node:?}"
            );
        }
        for entry in ECUS {
            assert_eq!(ecu(entry.node).map(|e| e.name), Some(entry.name));
            assert_eq!(by_name(entry.name).map(|e| e.node), Some(entry.node));
            assert_eq!(firmware_name(entry.node), entry.name);
            assert!(entry.step_period_us > 0 && !entry.signals.is_empty());
        }
        assert!(ecu(Node::Gateway).is_none());
    }
}
