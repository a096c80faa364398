//! The logging shim on the target: the macros the logic crates use resolve to defmt, and
//! their lines appear in the run's output (decoded by defmt-print / probe-rs).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_target_tests as _;

    #[test]
    fn the_shim_logs_through_defmt() {
        assert_eq!(autoplug_log::BACKEND, "defmt");
        let speed = 88.5f32;
        autoplug_log::info!("autoplug-log on target: cruise engaged at {} km/h", speed);
        autoplug_log::warn!("autoplug-log on target: stale input {:?}", Some(3u8));
        autoplug_log::error!("autoplug-log on target: dtc {}", 0x4A1u16);
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
