//! The two-copy persistent state over the simulated F446 flash: its records survive a power
//! cut at every flash operation, including the switch between copies.

use core::cell::RefCell;

use autoplug_flash::ab::BOOT_RECORD;
use autoplug_flash::sim::{state_twin, SimFlash};
use autoplug_flash::twin::{
    RecordKind, FLOOR_RECORD, KEY_FAILURES_RECORD, RECORDS_START, RECORD_LEN, SEED_EPOCH_RECORD,
};
use autoplug_flash::{SMALL_SECTOR_SIZE, STATE_COPIES};

const FLOOR: RecordKind = FLOOR_RECORD;
const ATTEMPTS: RecordKind = KEY_FAILURES_RECORD;
const EPOCH: RecordKind = SEED_EPOCH_RECORD;
const BOOT: RecordKind = BOOT_RECORD;

/// Record slots of one copy.
const SLOTS: u32 = (SMALL_SECTOR_SIZE - RECORDS_START) / RECORD_LEN;

fn record(flash: &RefCell<SimFlash>, kind: RecordKind) -> Option<u32> {
    let mut twin = state_twin(flash).expect("open");
    twin.read_record(kind)
        .expect("read")
        .map(u32::from_le_bytes)
}

fn write(flash: &RefCell<SimFlash>, kind: RecordKind, value: u32) -> Result<(), String> {
    let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
    twin.write_record(kind, value.to_le_bytes())
        .map_err(|e| e.to_string())
}

#[test]
fn a_new_board_reads_erased_and_the_first_write_creates_copy_a() {
    let flash = RefCell::new(SimFlash::new(1));
    let mut twin = state_twin(&flash).expect("open");
    assert_eq!(twin.sequence(), None);
    assert_eq!(twin.read_record(FLOOR), Ok(None));
    assert_eq!(twin.read_record(BOOT), Ok(None));
    assert_eq!(flash.borrow().operations(), 0, "reading writes nothing");

    twin.write_record(FLOOR, 7u32.to_le_bytes()).expect("write");
    assert_eq!((twin.sequence(), twin.current_copy()), (Some(1), Some(0)));
    assert_eq!(record(&flash, FLOOR), Some(7));
    assert_eq!(record(&flash, ATTEMPTS), None);
}

#[test]
fn the_latest_record_of_each_kind_survives_a_full_copy() {
    let flash = RefCell::new(SimFlash::new(2));
    write(&flash, FLOOR, 0x0001_0002).expect("floor");
    // Enough attempts records to fill copy A twice over.
    for n in 0..2 * SLOTS + 5 {
        write(&flash, ATTEMPTS, n).expect("attempts");
        assert_eq!(record(&flash, ATTEMPTS), Some(n));
    }
    let twin = state_twin(&flash).expect("open");
    assert_eq!(twin.sequence(), Some(3), "two switches");
    assert_eq!(record(&flash, FLOOR), Some(0x0001_0002), "carried over");
    assert_eq!(record(&flash, ATTEMPTS), Some(2 * SLOTS + 4));
    assert_eq!(flash.borrow().stats().reprogrammed_words, 0);
}

#[test]
fn copies_that_do_not_fit_the_layout_are_refused() {
    use autoplug_flash::sim::SimPartition;
    use autoplug_flash::twin::{Twin, TwinError};
    let flash = RefCell::new(SimFlash::new(5));
    let small = SimPartition::<SMALL_SECTOR_SIZE>::new(&flash, STATE_COPIES[0]).expect("a");
    let spare = SimPartition::<SMALL_SECTOR_SIZE>::new(
        &flash,
        autoplug_flash::Region {
            start: autoplug_flash::BOOTLOADER.start,
            size: 2 * SMALL_SECTOR_SIZE,
        },
    )
    .expect("two sectors");
    assert_eq!(Twin::open([small, spare]).err(), Some(TwinError::Geometry));
}

/// What a workload step does.
#[derive(Clone, Copy, Debug)]
enum Step {
    Record(RecordKind, u32),
}

/// What the store must read after each step: the value of each kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Seen {
    floor: Option<u32>,
    attempts: Option<u32>,
    epoch: Option<u32>,
    boot: Option<u32>,
}

fn seen(flash: &RefCell<SimFlash>) -> Seen {
    Seen {
        floor: record(flash, FLOOR),
        attempts: record(flash, ATTEMPTS),
        epoch: record(flash, EPOCH),
        boot: record(flash, BOOT),
    }
}

fn run(flash: &RefCell<SimFlash>, step: Step) -> Result<(), String> {
    let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
    match step {
        Step::Record(kind, value) => twin.write_record(kind, value.to_le_bytes()),
    }
    .map_err(|e| e.to_string())
}

/// A life of the store: records of four kinds, the boot record among them, and enough
/// attempt records to run a copy full twice (switches carrying the others).
fn workload() -> Vec<Step> {
    let mut steps = vec![
        Step::Record(FLOOR, 0x0001_0000),
        Step::Record(EPOCH, 1),
        Step::Record(BOOT, 0x0000_FF00),
    ];
    for n in 0..SLOTS + 2 {
        steps.push(Step::Record(ATTEMPTS, n % 4));
        if n == SLOTS / 2 {
            steps.push(Step::Record(BOOT, 0x0000_0100));
        }
    }
    steps.extend([
        Step::Record(FLOOR, 0x0002_0000),
        Step::Record(BOOT, 0x0000_0101),
        Step::Record(EPOCH, 2),
    ]);
    for n in 0..SLOTS {
        steps.push(Step::Record(ATTEMPTS, n % 3));
    }
    steps.push(Step::Record(BOOT, 0x0000_FF01));
    steps
}

/// A power cut at every flash operation of the workload, with several seeds for what the
/// interrupted operation leaves: after power returns, every value reads as before or after
/// the interrupted step, never older, never damaged, and the step done again completes it.
#[test]
fn a_power_cut_at_any_operation_loses_nothing() {
    let steps = workload();
    let flash = RefCell::new(SimFlash::new(0));
    let mut views = vec![seen(&flash)];
    let mut failures = Vec::new();
    let (mut cuts, mut switches) = (0, 0);
    for (i, &step) in steps.iter().enumerate() {
        let before = flash.borrow().clone();
        let ops_before = flash.borrow().operations();
        let sequence = state_twin(&flash).expect("open").sequence();
        run(&flash, step).expect("no cut");
        views.push(seen(&flash));
        let ops = flash.borrow().operations() - ops_before;
        if state_twin(&flash).expect("open").sequence() != sequence {
            switches += 1;
        }
        for seed in 1..=3u64 {
            for k in 0..ops {
                let cut = RefCell::new(before.clone());
                cut.borrow_mut().reseed(seed);
                cut.borrow_mut().cut_power_at(k);
                let outcome = run(&cut, step);
                assert!(
                    outcome.is_err() && !cut.borrow().is_powered(),
                    "step {i}, cut {k}"
                );
                cut.borrow_mut().restore_power();
                cuts += 1;
                let now = seen(&cut);
                let what = format!("seed {seed}, step {i} ({step:?}), cut at its operation {k}");
                if now != views[i] && now != views[i + 1] {
                    failures.push(format!(
                        "{what}: read {now:?}, expected {:?} or {:?}",
                        views[i],
                        views[i + 1]
                    ));
                } else if let Err(e) = run(&cut, step) {
                    failures.push(format!("{what}: done again: {e}"));
                } else if seen(&cut) != views[i + 1] {
                    failures.push(format!("{what}: done again, read {:?}", seen(&cut)));
                }
            }
        }
    }
    println!(
        "twin power-cut sweep: {} steps, {switches} copy switches, {cuts} cuts (3 seeds), {} failures",
        steps.len(),
        failures.len()
    );
    assert!(switches >= 3, "the workload switches copies");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
