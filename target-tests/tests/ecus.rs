//! Every ECU's logic on the Cortex-M4F: each ECU crate's shared test cases (its
//! `test_cases::CASES`, the same functions the host runs as `#[test]`s), for every ECU of the
//! registry (`autoplug_ecus::for_each_ecu!`), so an ECU added there is tested here too.
//!
//! Why not defmt-test: its `#[tests]` module must spell out each test function, and these
//! come from a table per ECU. This runner prints what defmt-test prints (`(i/n) running
//! `name`...`, `all tests passed!`, a semihosting exit), so the scripts read both alike; a
//! failing case ends the run through the transport's panic handler, as under defmt-test.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod on_target {
    use autoplug_target_tests as _;

    macro_rules! every_case {
        ($(($node:ident, $name:ident, $krate:ident, $logic:ident)),* $(,)?) => {
            /// Each ECU's name with its cases, in the registry's order.
            const SUITES: &[(&str, &[(&str, fn())])] =
                &[$((stringify!($name), autoplug_ecus::$name::test_cases::CASES)),*];
        };
    }
    autoplug_ecus::for_each_ecu!(every_case);

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let total: usize = SUITES.iter().map(|(_, cases)| cases.len()).sum();
        let mut number = 1;
        for (ecu, cases) in SUITES {
            for (case, run) in cases.iter() {
                defmt::println!(
                    "({=usize}/{=usize}) running `{=str}::{=str}`...",
                    number,
                    total,
                    ecu,
                    case
                );
                run();
                number += 1;
            }
        }
        defmt::println!("all tests passed!");
        semihosting::process::exit(0)
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
