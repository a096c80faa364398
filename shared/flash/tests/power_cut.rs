//! A firmware update survives a power cut at any moment.
//!
//! The update and boot logic of `autoplug_flash::ab` — the application's download into the
//! slot that is not running, its trial mark and confirmation, the bootloader's choice at
//! every reset — runs over the simulated F446 flash, exactly as on the ECU. One run per flash
//! operation of the update cuts the power at that operation; after power returns, every
//! reset must start a slot holding, byte for byte, the old image or the new one (never a
//! partial one: a *brick*), and the ECU must end consistent: the new image confirmed, or the
//! old one running confirmed, from which a retry succeeds.
//!
//! The image contents are opaque here but for a vector table the bootloader can judge; the
//! signature check before the trial mark is the image crate's (`autoplug-image`), and the
//! download stands for it with a read-back comparison.

use core::cell::RefCell;
use std::time::Duration;

use autoplug_flash::ab::{self, BootAction, BootState, ImageSlot};
use autoplug_flash::sim::{state_twin, FlashOp, SimFlash, SlotPartition};
use autoplug_flash::twin::FLOOR_RECORD;
use autoplug_flash::{ERASE_VALUE, IMAGE_HEADER_SIZE, SLOT_ERASE_SIZE, WRITE_SIZE};
use embedded_storage::nor_flash::{NorFlash, ReadNorFlash};

/// Bytes of a test image (header ‖ payload ‖ signature, opaque here but for the vector
/// table): 64 KiB and the 576 bytes of header and signature, like the largest firmware.
const IMAGE_LEN: usize = 64 * 1024 + 576;
/// Bytes per flash program: a UDS TransferData block (4094) cut to whole words, as the
/// server writes them.
const TRANSFER_BLOCK: usize = 4092;
/// Seed of the flash's interrupted-operation generator in the main sweep.
const FLASH_SEED: u64 = 0x00A0_7091_F1A5_4000;

/// A reproducible byte stream for the image contents (SplitMix64).
fn seeded_bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut state = seed;
    let mut bytes = Vec::with_capacity(len + 8);
    while bytes.len() < len {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        bytes.extend_from_slice(&(z ^ (z >> 31)).to_le_bytes());
    }
    bytes.truncate(len);
    bytes
}

/// A test image linked for `slot`: seeded bytes with a plausible vector table (initial stack
/// pointer at the top of SRAM, a Thumb reset handler in the slot), padded to whole words.
fn image_for(seed: u64, slot: ImageSlot) -> Vec<u8> {
    let mut bytes = seeded_bytes(seed, IMAGE_LEN);
    let table = IMAGE_HEADER_SIZE as usize;
    let stack_top = autoplug_flash::SRAM_START + autoplug_flash::SRAM_SIZE;
    bytes[table..table + 4].copy_from_slice(&stack_top.to_le_bytes());
    bytes[table + 4..table + 8].copy_from_slice(&(slot.vector_table() + 0x401).to_le_bytes());
    bytes.resize(bytes.len().div_ceil(WRITE_SIZE) * WRITE_SIZE, ERASE_VALUE);
    bytes
}

/// The old image (factory, slot A) and the update (slot B).
struct Bench {
    old: Vec<u8>,
    new: Vec<u8>,
}

impl Bench {
    fn new() -> Self {
        Bench {
            old: image_for(1, ImageSlot::A),
            new: image_for(2, ImageSlot::B),
        }
    }

    fn image(&self, slot: ImageSlot) -> &[u8] {
        match slot {
            ImageSlot::A => &self.old,
            ImageSlot::B => &self.new,
        }
    }
}

/// A board from the factory: the old image in slot A, its version floor recorded (so the
/// state's first copy exists) but no boot record, slot B holding whatever an earlier life
/// left (here: an unrelated image).
fn factory(seed: u64, bench: &Bench) -> RefCell<SimFlash> {
    let mut flash = SimFlash::new(seed);
    flash
        .program(ImageSlot::A.region().start, &bench.old)
        .expect("factory programming");
    flash
        .program(ImageSlot::B.region().start, &image_for(99, ImageSlot::B))
        .expect("an earlier image in slot B");
    let flash = RefCell::new(flash);
    state_twin(&flash)
        .and_then(|mut twin| twin.write_record(FLOOR_RECORD, [1, 0, 0, 0]))
        .expect("factory floor");
    flash
}

/// Whether a slot holds a startable vector table (what the bootloader checks).
fn startable(flash: &RefCell<SimFlash>, slot: ImageSlot) -> bool {
    let mut words = [0u8; 8];
    let ok = SlotPartition::slot(flash, slot)
        .read(IMAGE_HEADER_SIZE, &mut words)
        .is_ok();
    let word = |i: usize| u32::from_le_bytes(words[i..i + 4].try_into().expect("4 bytes"));
    ok && ab::plausible_vector_table(slot, word(0), word(4))
}

/// A reset: the bootloader's choice (recorded as it decides).
fn reset(flash: &RefCell<SimFlash>) -> ab::BootChoice {
    match state_twin(flash) {
        Ok(mut twin) => ab::choose(&mut twin, |slot| startable(flash, slot)),
        Err(e) => panic!("the state copies always open in the simulation: {e}"),
    }
}

/// What the application reads of its standing at its start.
fn app_state(flash: &RefCell<SimFlash>, running: ImageSlot) -> Result<BootState, String> {
    let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
    ab::state(&mut twin, running).map_err(|e| e.to_string())
}

/// The application's download of `image` into the slot that is not `running`: unmark,
/// erase the sectors the image needs, write it in TransferData blocks, read it back, mark
/// it for trial.
fn download(flash: &RefCell<SimFlash>, running: ImageSlot, image: &[u8]) -> Result<(), String> {
    let target = running.other();
    {
        let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
        ab::prepare_download(&mut twin, running, target).map_err(|e| format!("{e:?}"))?;
    }
    let mut slot = SlotPartition::slot(flash, target);
    let erase_end = (image.len() as u32).div_ceil(SLOT_ERASE_SIZE) * SLOT_ERASE_SIZE;
    slot.erase(0, erase_end).map_err(|e| e.to_string())?;
    for (i, block) in image.chunks(TRANSFER_BLOCK).enumerate() {
        // Blocks are whole words but the last (the image is padded to words).
        slot.write((i * TRANSFER_BLOCK) as u32, block)
            .map_err(|e| e.to_string())?;
    }
    let mut back = vec![0u8; image.len()];
    slot.read(0, &mut back).map_err(|e| e.to_string())?;
    if back != image {
        return Err("the image does not read back".into());
    }
    let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
    ab::mark_trial(&mut twin, running, target).map_err(|e| format!("{e:?}"))
}

fn confirm(flash: &RefCell<SimFlash>, running: ImageSlot) -> Result<(), String> {
    let mut twin = state_twin(flash).map_err(|e| e.to_string())?;
    ab::confirm(&mut twin, running).map_err(|e| e.to_string())
}

/// Whether `slot` holds exactly the image the bench put there for it.
fn holds_its_image(flash: &RefCell<SimFlash>, bench: &Bench, slot: ImageSlot) -> bool {
    let image = bench.image(slot);
    let mut bytes = vec![0u8; image.len()];
    SlotPartition::slot(flash, slot)
        .read(0, &mut bytes)
        .is_ok_and(|()| bytes == image)
}

/// The whole update from the factory state: download, reset into the trial, confirm.
fn update(flash: &RefCell<SimFlash>, bench: &Bench) -> Result<(), String> {
    download(flash, ImageSlot::A, &bench.new)?;
    let choice = reset(flash);
    if choice.slot != ImageSlot::B || app_state(flash, ImageSlot::B)? != BootState::Trial {
        return Err(format!("the reset after the download started {choice:?}"));
    }
    confirm(flash, ImageSlot::B)
}

/// Flash operations of an uninterrupted update.
fn update_operations(bench: &Bench) -> u64 {
    let flash = factory(FLASH_SEED, bench);
    let before = flash.borrow().operations();
    update(&flash, bench).expect("an uninterrupted update");
    let after = flash.borrow().operations();
    after - before
}

/// What a run with a cut ended in.
#[derive(Default, Debug)]
struct Tally {
    cuts: u64,
    /// The first reset after the cut started the old image / the new one.
    first_old: u64,
    first_new: u64,
    /// A reset started a slot without its complete image.
    bricks: Vec<String>,
    /// The ECU did not end on the new image confirmed after the retry.
    inconsistent: Vec<String>,
}

/// Update with a cut at operation `k`, then what the ECU does after power returns: reset,
/// confirm a trial that runs, retry the update from the old image, until the new one runs
/// confirmed.
fn cut_run(seed: u64, k: u64, bench: &Bench, tally: &mut Tally) {
    let flash = factory(seed, bench);
    flash.borrow_mut().cut_power_at(k);
    let outcome = update(&flash, bench);
    if flash.borrow().is_powered() {
        // The cut fell after the last operation: nothing was cut.
        flash.borrow_mut().cancel_cut();
        assert!(outcome.is_ok(), "cut {k}: {outcome:?}");
        return;
    }
    flash.borrow_mut().restore_power();
    tally.cuts += 1;
    for attempt in 0..3 {
        let choice = reset(&flash);
        if !holds_its_image(&flash, bench, choice.slot) {
            tally.bricks.push(format!(
                "seed {seed:#x}, cut {k}: reset {attempt} started {choice:?}"
            ));
            return;
        }
        let state = app_state(&flash, choice.slot);
        if attempt == 0 {
            match choice.slot {
                ImageSlot::A => tally.first_old += 1,
                ImageSlot::B => tally.first_new += 1,
            }
        }
        let done = match (choice.slot, state) {
            (ImageSlot::B, Ok(BootState::Trial)) => confirm(&flash, ImageSlot::B),
            (ImageSlot::B, Ok(_)) => Ok(()),
            (ImageSlot::A, Ok(BootState::Confirmed | BootState::Reverted)) => {
                download(&flash, ImageSlot::A, &bench.new)
            }
            (slot, state) => Err(format!("slot {slot:?} runs in state {state:?}")),
        };
        if let Err(e) = done {
            tally
                .inconsistent
                .push(format!("seed {seed:#x}, cut {k}: {e}"));
            return;
        }
        if choice.slot == ImageSlot::B
            && app_state(&flash, ImageSlot::B) == Ok(BootState::Confirmed)
        {
            return;
        }
    }
    tally.inconsistent.push(format!(
        "seed {seed:#x}, cut {k}: the new image never ran confirmed"
    ));
}

fn sweep(seed: u64, bench: &Bench) -> Tally {
    let mut tally = Tally::default();
    for k in 0..update_operations(bench) {
        cut_run(seed, k, bench, &mut tally);
    }
    tally
}

/// The main sweep: a cut at every flash operation of the update (the erase of the slot,
/// each block, the records), 0 bricks, and every run ends on the new image confirmed.
#[test]
fn update_survives_a_power_cut_at_every_operation() {
    let bench = Bench::new();
    let ops = update_operations(&bench);
    // Unmarking needs no write from the factory state; then 1 erase, 17 blocks, the mark,
    // the trial record at the reset, the confirmation.
    assert_eq!(ops, 1 + IMAGE_LEN.div_ceil(TRANSFER_BLOCK) as u64 + 3);
    let tally = sweep(FLASH_SEED, &bench);
    println!(
        "A/B update power-cut sweep: {ops} operations, {} cuts; first reset after the cut ran \
         the old image {} times, the new one {}; {} bricks, {} inconsistent ends",
        tally.cuts,
        tally.first_old,
        tally.first_new,
        tally.bricks.len(),
        tally.inconsistent.len()
    );
    assert_eq!(tally.cuts, ops);
    assert!(tally.bricks.is_empty(), "{:#?}", tally.bricks);
    assert!(tally.inconsistent.is_empty(), "{:#?}", tally.inconsistent);
    // Cuts before the trial record leave the old image running; after it, the new one.
    assert!(tally.first_old > 0 && tally.first_new > 0, "{tally:?}");
}

/// The same sweep with other seeds for what an interrupted operation leaves.
#[test]
fn update_survives_power_cuts_with_other_seeds() {
    let bench = Bench::new();
    for seed in [1, 2, 0xDEAD_BEEF, 0x5EED_0000_0000_0001] {
        let tally = sweep(seed, &bench);
        assert!(tally.bricks.is_empty(), "{:#?}", tally.bricks);
        assert!(tally.inconsistent.is_empty(), "{:#?}", tally.inconsistent);
    }
}

/// A new image that never confirms itself (it crashes before its self-test passes) is
/// reverted at the next reset, whatever operation of that reset a cut hits; the old image
/// then runs, stating the revert, and takes the next download.
#[test]
fn an_unconfirmed_image_reverts_even_with_a_power_cut() {
    let bench = Bench::new();
    let trial = || {
        let flash = factory(FLASH_SEED, &bench);
        download(&flash, ImageSlot::A, &bench.new).expect("download");
        let choice = reset(&flash);
        assert_eq!(
            (choice.slot, choice.action),
            (ImageSlot::B, BootAction::Trial)
        );
        flash
    };
    // Uncut: the next reset reverts.
    let flash = trial();
    let before = flash.borrow().operations();
    let choice = reset(&flash);
    let revert_ops = flash.borrow().operations() - before;
    assert_eq!(
        (choice.slot, choice.action),
        (ImageSlot::A, BootAction::Reverted)
    );
    assert_eq!(app_state(&flash, ImageSlot::A), Ok(BootState::Reverted));
    assert_eq!(revert_ops, 1, "one record");
    // A cut at the revert's record: still the old image, and it keeps reverting.
    for k in 0..revert_ops {
        let flash = trial();
        flash.borrow_mut().cut_power_at(k);
        let cut = reset(&flash);
        assert_eq!(
            cut.slot,
            ImageSlot::A,
            "a cut revert still starts the old image"
        );
        flash.borrow_mut().restore_power();
        let again = reset(&flash);
        assert_eq!(again.slot, ImageSlot::A);
        assert!(holds_its_image(&flash, &bench, ImageSlot::A));
        let state = app_state(&flash, ImageSlot::A).expect("state");
        assert!(matches!(state, BootState::Reverted), "{state:?}");
        download(&flash, ImageSlot::A, &bench.new).expect("the next download");
    }
    // Resets keep running the old image; the reverted trial is never started again.
    let flash = trial();
    for _ in 0..3 {
        assert_eq!(reset(&flash).slot, ImageSlot::A);
    }
    assert_eq!(app_state(&flash, ImageSlot::A), Ok(BootState::Reverted));
}

/// A slot marked for trial and then downloaded again before any reset (a second tester
/// session) is unmarked before its erase: a cut anywhere in the second download never
/// starts the half-written slot.
#[test]
fn a_second_download_unmarks_the_slot_before_erasing_it() {
    let bench = Bench::new();
    let marked = || {
        let flash = factory(FLASH_SEED, &bench);
        download(&flash, ImageSlot::A, &bench.new).expect("first download");
        flash
    };
    let flash = marked();
    let before = flash.borrow().operations();
    download(&flash, ImageSlot::A, &bench.new).expect("second download");
    let ops = flash.borrow().operations() - before;
    assert_eq!(ops, 1 + 1 + IMAGE_LEN.div_ceil(TRANSFER_BLOCK) as u64 + 1);
    for k in 0..ops {
        let flash = marked();
        flash.borrow_mut().cut_power_at(k);
        assert!(download(&flash, ImageSlot::A, &bench.new).is_err());
        flash.borrow_mut().restore_power();
        let choice = reset(&flash);
        assert!(
            holds_its_image(&flash, &bench, choice.slot),
            "cut {k}: started {choice:?}"
        );
    }
}

/// The rules the application keeps: no download while on trial, never into the running
/// slot.
#[test]
fn downloads_are_refused_while_on_trial_and_into_the_running_slot() {
    let bench = Bench::new();
    let flash = factory(FLASH_SEED, &bench);
    {
        let mut twin = state_twin(&flash).expect("open");
        assert!(matches!(
            ab::prepare_download(&mut twin, ImageSlot::A, ImageSlot::A),
            Err(ab::AbError::SlotInUse(ImageSlot::A))
        ));
    }
    download(&flash, ImageSlot::A, &bench.new).expect("download");
    assert_eq!(reset(&flash).slot, ImageSlot::B);
    let mut twin = state_twin(&flash).expect("open");
    assert!(matches!(
        ab::prepare_download(&mut twin, ImageSlot::B, ImageSlot::A),
        Err(ab::AbError::Unconfirmed)
    ));
    ab::confirm(&mut twin, ImageSlot::B).expect("confirm");
    ab::prepare_download(&mut twin, ImageSlot::B, ImageSlot::A).expect("now it may");
}

/// A board whose record names a slot that holds nothing startable (an erased slot, a probe
/// that wrote only one) starts the other.
#[test]
fn the_bootloader_falls_back_to_a_startable_slot() {
    let bench = Bench::new();
    let flash = RefCell::new(SimFlash::new(3));
    flash
        .borrow_mut()
        .program(ImageSlot::B.region().start, &bench.new)
        .expect("program B");
    let choice = reset(&flash);
    assert_eq!(
        (choice.slot, choice.action),
        (ImageSlot::B, BootAction::Fallback)
    );
    assert_eq!(
        flash.borrow().operations(),
        1,
        "the fallback writes nothing"
    );
}

/// The simulated busy time of an uninterrupted update of a 64 KiB image, against the
/// datasheet arithmetic: 16 µs per word, 1 s per 128 KiB sector (DS10693, typ., x32). No
/// copy at the reset, no state sector erase.
#[test]
fn update_busy_time_follows_the_datasheet() {
    let bench = Bench::new();
    let flash = factory(FLASH_SEED, &bench);
    let word = Duration::from_micros(16);
    let erase_128k = Duration::from_millis(1000);
    let busy = || flash.borrow().total_busy();
    let image_words = (bench.new.len() / WRITE_SIZE) as u32; // 16 528

    let t0 = busy();
    download(&flash, ImageSlot::A, &bench.new).expect("download");
    let download_time = busy() - t0;
    // The one sector, the blocks, the mark (a two-word record).
    assert_eq!(download_time, erase_128k + word * (image_words + 2));

    let t0 = busy();
    assert_eq!(reset(&flash).action, BootAction::Trial);
    let reset_time = busy() - t0;
    assert_eq!(reset_time, word * 2, "one record, no copy");

    let t0 = busy();
    confirm(&flash, ImageSlot::B).expect("confirm");
    let confirm_time = busy() - t0;
    assert_eq!(confirm_time, word * 2);

    let total = download_time + reset_time + confirm_time;
    assert_eq!(total, Duration::from_micros(1_264_544));
    let traced = factory(FLASH_SEED, &bench);
    traced.borrow_mut().record_trace(true);
    update(&traced, &bench).expect("update");
    let erases = traced
        .borrow()
        .trace()
        .iter()
        .filter(|op| matches!(op, FlashOp::Erase { .. }))
        .count();
    assert_eq!(erases, 1, "one sector erase in the whole update");
    println!(
        "64 KiB update, simulated flash busy time: download {download_time:?}, reset \
         {reset_time:?}, confirm {confirm_time:?}, total {total:?}"
    );
}
