//! The nine ECUs by the short names people type (`cruise`, `abs`...): the command line,
//! scenario files, the gateway's inventory and the fleet all name them so.

use crate::Node;

/// The nine ECUs with a diagnostic address, in the DBC's order.
pub const ECUS: [Node; 9] = [
    Node::Engine,
    Node::Pedals,
    Node::Steering,
    Node::Transmission,
    Node::Cabin,
    Node::Console,
    Node::Differential,
    Node::Cruise,
    Node::ABS,
];

/// Each ECU's short name, then the aliases (`trans`, `diff`).
const NAMES: [(&str, Node); 11] = [
    ("engine", Node::Engine),
    ("pedals", Node::Pedals),
    ("steering", Node::Steering),
    ("transmission", Node::Transmission),
    ("cabin", Node::Cabin),
    ("console", Node::Console),
    ("differential", Node::Differential),
    ("cruise", Node::Cruise),
    ("abs", Node::ABS),
    ("trans", Node::Transmission),
    ("diff", Node::Differential),
];

/// The names [`parse_ecu`] accepts, for help texts and error messages.
pub const ECU_NAME_LIST: &str =
    "engine, pedals, steering, transmission (trans), cabin, console, differential (diff), cruise, abs";

/// The ECU called `name` (ASCII case ignored, surrounding spaces too; aliases `trans` and
/// `diff`).
pub fn parse_ecu(name: &str) -> Option<Node> {
    let wanted = name.trim();
    NAMES
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(wanted))
        .map(|(_, node)| *node)
}

/// The short name of an ECU (`"cruise"`); the DBC name for the gateway.
pub fn ecu_name(node: Node) -> &'static str {
    NAMES
        .iter()
        .find(|(_, n)| *n == node)
        .map_or_else(|| node.name(), |(name, _)| *name)
}

/// The name of an ECU's crate and firmware (`ecu-trans`, `trans-fw`): the short name, or
/// its alias where the crate took one.
pub fn firmware_name(node: Node) -> &'static str {
    match node {
        Node::Transmission => "trans",
        Node::Differential => "diff",
        other => ecu_name(other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_ecu_has_one_name_that_parses_back() {
        for node in ECUS {
            assert_eq!(parse_ecu(ecu_name(node)), Some(node));
        }
        assert_eq!(parse_ecu(" Trans "), Some(Node::Transmission));
        assert_eq!(parse_ecu("DIFF"), Some(Node::Differential));
        assert_eq!(parse_ecu("gateway"), None);
        assert_eq!(ecu_name(Node::Transmission), "transmission");
    }
}
