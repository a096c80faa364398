//! The ECUs by the names people type (`cruise`, `abs`...): the command line, scenario
//! files, the gateway's inventory and the fleet all name them so. Both the list and the
//! names come from the DBC: its nodes with a diagnostic address, their names in lower case.

use crate::Node;

/// The ECUs (the nodes with a diagnostic address), in the DBC's order.
pub const ECUS: [Node; Node::ECUS.len()] = Node::ECUS;

/// The names [`parse_ecu`] accepts, for help texts and error messages.
pub const ECU_NAME_LIST: &str = Node::ECU_NAMES;

/// The shortest start of a name that [`parse_ecu`] takes for the whole (`trans`, `diff`).
const MIN_PREFIX: usize = 4;

/// The ECU called `name`: its name or, of four letters or more, the start of exactly one
/// ECU's name (`trans`, `diff`); ASCII case and surrounding spaces ignored.
pub fn parse_ecu(name: &str) -> Option<Node> {
    let wanted = name.trim();
    if let Some(node) = ECUS
        .iter()
        .find(|node| node.short_name().eq_ignore_ascii_case(wanted))
    {
        return Some(*node);
    }
    if wanted.len() < MIN_PREFIX {
        return None;
    }
    let mut starting = ECUS.iter().filter(|node| {
        node.short_name()
            .get(..wanted.len())
            .is_some_and(|start| start.eq_ignore_ascii_case(wanted))
    });
    match (starting.next(), starting.next()) {
        (Some(node), None) => Some(*node),
        _ => None,
    }
}

/// The name of an ECU as people type it (`"cruise"`); the DBC name for another node
/// (the gateway).
pub fn ecu_name(node: Node) -> &'static str {
    if ECUS.contains(&node) {
        node.short_name()
    } else {
        node.name()
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
        assert_eq!(parse_ecu("cruis"), Some(Node::Cruise));
        assert_eq!(parse_ecu("gateway"), None);
        assert_eq!(parse_ecu("ab"), None, "too short to stand for abs");
        assert_eq!(parse_ecu("cabinet"), None, "longer than any name");
        assert_eq!(ecu_name(Node::Transmission), "transmission");
        assert_eq!(ecu_name(Node::Gateway), "Gateway");
        assert!(
            ECU_NAME_LIST.starts_with("engine, pedals"),
            "{ECU_NAME_LIST}"
        );
    }
}
