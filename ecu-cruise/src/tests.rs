use crate::test_cases;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    publishes_speed_and_command_at_their_periods,
    engages_on_the_edge_and_latches_the_speed,
    a_stray_on_after_a_cancel_does_not_engage,
    holds_speed_and_rejects_a_grade,
    stale_cruise_mode_disengages,
    faulty_build_oscillates,
);
