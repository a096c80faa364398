//! `autoplug_can::test_cases` on the Cortex-M4F: the generated codec, swept over every raw
//! value of every signal, as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_can::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn catalogue_matches_the_spec() {
        test_cases::catalogue_matches_the_spec();
    }

    #[test]
    fn nodes_match_the_spec() {
        test_cases::nodes_match_the_spec();
    }

    #[test]
    fn diagnostic_identifiers_follow_spec_section_4() {
        test_cases::diagnostic_identifiers_follow_spec_section_4();
    }

    #[test]
    fn every_valid_raw_value_round_trips() {
        test_cases::every_valid_raw_value_round_trips();
    }

    #[test]
    fn invalid_raw_values_are_rejected() {
        test_cases::invalid_raw_values_are_rejected();
    }

    #[test]
    fn wrong_length_is_rejected() {
        test_cases::wrong_length_is_rejected();
    }

    #[test]
    fn unknown_identifiers_are_rejected() {
        test_cases::unknown_identifiers_are_rejected();
    }

    #[test]
    fn sending_clamps() {
        test_cases::sending_clamps();
    }

    #[test]
    fn typed_messages_follow_the_spec() {
        test_cases::typed_messages_follow_the_spec();
    }

    #[test]
    fn update_keeps_the_last_good_value() {
        test_cases::update_keeps_the_last_good_value();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
