//! The same scenario run twice gives byte-identical outputs (trace, bus log, summary, plots).

use autoplug_host_tests::*;
use autoplug_virtual_car::report::write_outputs;
use std::fs;

#[test]
fn the_same_scenario_gives_byte_identical_outputs() {
    let s = scenario("drive-cycle");
    let base = std::env::temp_dir().join(format!("autoplug-determinism-{}", std::process::id()));
    let (a, b) = (base.join("a"), base.join("b"));
    write_outputs(&a, &run(&s)).unwrap();
    write_outputs(&b, &run(&s)).unwrap();
    let mut names: Vec<_> = fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert!(names.len() >= 9, "{names:?}");
    for name in &names {
        let (x, y) = (
            fs::read(a.join(name)).unwrap(),
            fs::read(b.join(name)).unwrap(),
        );
        assert!(!x.is_empty(), "{name:?} is empty");
        assert!(x == y, "{name:?} differs between two runs");
    }
    // And a different seed gives a different bus log timing or sensor noise.
    let mut other = s.clone();
    other.seed += 1;
    let c = base.join("c");
    write_outputs(&c, &run(&other)).unwrap();
    assert_ne!(
        fs::read(a.join("trace.csv")).unwrap(),
        fs::read(c.join("trace.csv")).unwrap()
    );
    fs::remove_dir_all(&base).unwrap();
}
