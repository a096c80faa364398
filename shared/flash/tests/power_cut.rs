//! A firmware update survives a power cut at any moment.
//!
//! embassy-boot 0.7's own logic (the application's `BlockingFirmwareUpdater` and
//! `BlockingFirmwareState`, the bootloader's `BootLoader::prepare_boot`) runs over the
//! simulated F446 flash and its partitions, exactly as it will on the ECU. One run per flash
//! operation of the update cuts the power at that operation; after power returns, every reset
//! must find the active slot holding byte for byte the old image or the new one, never
//! anything else, and the ECU must end consistent (new image confirmed, or old image running
//! with no update pending, from which a retry succeeds).
//!
//! The complete images are never lost, and neither is a pending rollback. embassy-boot's
//! state lives in the two-copy store of `autoplug_flash::twin`: its erase of the state
//! partition prepares the other copy and switches only once that copy is complete, so a cut
//! there leaves the previous state whole. Over a single state sector (embassy-boot 0.7 as
//! shipped) a torn erase that left the magic reading SWAP with the progress validity word
//! erased made the next reset swap again and, after a revert, left the unconfirmed image
//! running with nothing pending; `state_erase_cuts_with_many_seeds` tries those cuts with
//! many seeds and requires 0 lost rollbacks. What the sweeps still print about embassy-boot:
//! a cut at the swap's last progress word can make the next reset revert before the new image
//! ever ran, and a cut at the start of the confirmation can leave the new image running with
//! state `Revert` (both end on a complete, consistent image).

use core::cell::RefCell;
use std::fmt::Write as _;
use std::time::Duration;

use autoplug_flash::sim::{state_twin, FlashError, FlashOp, SimFlash, SlotPartition};
use autoplug_flash::{
    ACTIVE, BOOT_PAGE_SIZE, BOOT_SWAP_BUFFER_SIZE, DFU, ERASE_VALUE, SLOT_ERASE_SIZE, STATE_COPIES,
    WRITE_SIZE,
};
use embassy_boot::{
    AlignedBuffer, BlockingFirmwareState, BlockingFirmwareUpdater, BootError, BootLoader,
    BootLoaderConfig, FirmwareUpdaterConfig, FirmwareUpdaterError, State,
};
use embedded_storage::nor_flash::NorFlashErrorKind;

/// Opening the state copies failed (only a flash read can fail, and the simulation's never
/// does): reported as the flash error embassy-boot would see.
const OPEN_FAILED: NorFlashErrorKind = NorFlashErrorKind::Other;

/// Signed bytes of a test image (header ‖ payload, opaque here): 64 KiB.
const UPDATE_LEN: usize = 64 * 1024;
/// The Ed25519 signature appended after the signed bytes.
const SIGNATURE_LEN: usize = 64;
/// Size of a UDS TransferData block, as the CAN download writes them.
const TRANSFER_BLOCK: usize = 4096;
/// Seed of the signing key pair (a test key, never a real one).
const KEY_SEED: [u8; 32] = *b"autoplug power-cut test key seed";
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

/// A signed test image: `signed bytes ‖ signature`, the signature being Ed25519 over
/// SHA-512 of the signed bytes (what embassy-boot's `ed25519-salty` verification checks).
struct Image {
    bytes: Vec<u8>,
    /// What the active slot holds when this image is installed: the image, then erased flash.
    slot: Vec<u8>,
}

impl Image {
    fn new(seed: u64, keypair: &salty::Keypair) -> Self {
        let mut bytes = seeded_bytes(seed, UPDATE_LEN);
        let digest = salty::Sha512::new().updated(&bytes).finalize();
        bytes.extend_from_slice(&keypair.sign(&digest).to_bytes());
        let mut slot = bytes.clone();
        slot.resize(ACTIVE.size as usize, ERASE_VALUE);
        Image { bytes, slot }
    }
}

struct Bench {
    public_key: [u8; 32],
    /// What ran before the old image (an earlier update's backup in the DFU slot).
    older: Image,
    old: Image,
    new: Image,
}

impl Bench {
    fn new() -> Self {
        let keypair = salty::Keypair::from(&KEY_SEED);
        let bench = Bench {
            public_key: keypair.public.to_bytes(),
            older: Image::new(0, &keypair),
            old: Image::new(1, &keypair),
            new: Image::new(2, &keypair),
        };
        assert_eq!(bench.new.bytes.len(), UPDATE_LEN + SIGNATURE_LEN);
        assert_ne!(bench.old.bytes, bench.new.bytes);
        bench
    }
}

/// Which image the active slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Running {
    Old,
    New,
}

/// Why the simulated ECU stopped.
enum Halt {
    Updater(FirmwareUpdaterError),
    Boot(BootError),
    /// A check of this test failed.
    Broken(String),
}

impl std::fmt::Display for Halt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Halt::Updater(error) => write!(f, "the updater failed: {error:?}"),
            Halt::Boot(error) => write!(f, "the bootloader failed: {error:?}"),
            Halt::Broken(why) => write!(f, "{why}"),
        }
    }
}

impl From<FirmwareUpdaterError> for Halt {
    fn from(error: FirmwareUpdaterError) -> Self {
        Halt::Updater(error)
    }
}

impl From<BootError> for Halt {
    fn from(error: BootError) -> Self {
        Halt::Boot(error)
    }
}

/// The old application downloads the image into the DFU slot, as the UDS server does:
/// erase the sectors the image needs (not the whole slot: the swap erases the rest before
/// it copies there), then one write per 4 KiB block. embassy-boot's `write_firmware`
/// erases each sector as the first block reaches it.
fn download(flash: &RefCell<SimFlash>, image: &Image) -> Result<(), FirmwareUpdaterError> {
    let mut aligned = [0; WRITE_SIZE];
    let mut twin = state_twin(flash).map_err(|_| FirmwareUpdaterError::Flash(OPEN_FAILED))?;
    let config = FirmwareUpdaterConfig {
        dfu: SlotPartition::dfu(flash),
        state: twin.boot_state(),
    };
    let mut updater = BlockingFirmwareUpdater::new(config, &mut aligned);
    for (i, block) in image.bytes.chunks(TRANSFER_BLOCK).enumerate() {
        updater.write_firmware(i * TRANSFER_BLOCK, block)?;
    }
    Ok(())
}

/// The old application reads the signature that follows the signed bytes, verifies the
/// download and marks it for the swap.
fn verify_and_mark(
    flash: &RefCell<SimFlash>,
    public_key: &[u8; 32],
) -> Result<(), FirmwareUpdaterError> {
    let mut aligned = [0; WRITE_SIZE];
    let mut twin = state_twin(flash).map_err(|_| FirmwareUpdaterError::Flash(OPEN_FAILED))?;
    let config = FirmwareUpdaterConfig {
        dfu: SlotPartition::dfu(flash),
        state: twin.boot_state(),
    };
    let mut updater = BlockingFirmwareUpdater::new(config, &mut aligned);
    let mut signature = [0; SIGNATURE_LEN];
    updater.read_dfu(UPDATE_LEN as u32, &mut signature)?;
    updater.verify_and_mark_updated(public_key, &signature, UPDATE_LEN as u32)
}

/// A reset: the bootloader's `prepare_boot`, as at every reset.
fn reset(flash: &RefCell<SimFlash>) -> Result<State, BootError> {
    let mut twin = state_twin(flash).map_err(|_| BootError::Flash(OPEN_FAILED))?;
    let mut bootloader = BootLoader::new(BootLoaderConfig {
        active: SlotPartition::active(flash),
        dfu: SlotPartition::dfu(flash),
        state: twin.boot_state(),
    });
    let mut buffer = AlignedBuffer([0; BOOT_SWAP_BUFFER_SIZE]);
    bootloader.prepare_boot(buffer.as_mut())
}

/// The state as the running application sees it.
fn app_state(flash: &RefCell<SimFlash>) -> Result<State, FirmwareUpdaterError> {
    let mut aligned = [0; WRITE_SIZE];
    let mut twin = state_twin(flash).map_err(|_| FirmwareUpdaterError::Flash(OPEN_FAILED))?;
    BlockingFirmwareState::new(twin.boot_state(), &mut aligned).get_state()
}

/// The running application passed its self-test and confirms itself.
fn confirm(flash: &RefCell<SimFlash>) -> Result<(), FirmwareUpdaterError> {
    let mut aligned = [0; WRITE_SIZE];
    let mut twin = state_twin(flash).map_err(|_| FirmwareUpdaterError::Flash(OPEN_FAILED))?;
    BlockingFirmwareState::new(twin.boot_state(), &mut aligned).mark_booted()
}

/// Which image the active slot holds, byte for byte, or what it looks like if neither.
fn running(flash: &RefCell<SimFlash>, bench: &Bench) -> Result<Running, String> {
    let flash = flash.borrow();
    let active = flash.contents(ACTIVE).map_err(|e| e.to_string())?;
    if active == bench.old.slot.as_slice() {
        Ok(Running::Old)
    } else if active == bench.new.slot.as_slice() {
        Ok(Running::New)
    } else {
        let differs = |slot: &[u8]| active.iter().zip(slot).filter(|(a, b)| a != b).count();
        Err(format!(
            "the active slot holds neither image: {} bytes differ from the old one, {} from the new one",
            differs(&bench.old.slot),
            differs(&bench.new.slot)
        ))
    }
}

/// An ECU fresh from the factory: the old image in the active slot, confirmed (state Boot).
fn factory(seed: u64, bench: &Bench) -> RefCell<SimFlash> {
    let flash = RefCell::new(SimFlash::new(seed));
    flash
        .borrow_mut()
        .program(ACTIVE.start, &bench.old.bytes)
        .expect("the factory programs the old image");
    // The DFU slot's second sector holds what an earlier update's swap left there (the
    // image before the old one): the download does not erase it, the swap must.
    flash
        .borrow_mut()
        .program(DFU.start + SLOT_ERASE_SIZE, &bench.older.bytes)
        .expect("an earlier update left its backup");
    confirm(&flash).expect("the old image confirms itself");
    assert_eq!(reset(&flash).expect("the factory reset boots"), State::Boot);
    assert_eq!(running(&flash, bench), Ok(Running::Old));
    flash
}

/// The phases of an update, for the diagnostics.
const PHASES: [&str; 4] = [
    "download (prepare_update, TransferData)",
    "verify_and_mark_updated",
    "swap at the next reset",
    "confirmation (mark_booted)",
];

/// The whole update, from the old application running to the new one confirmed. Pushes the
/// operation count at the start of each phase onto `starts`. Stops at the first error.
fn update(flash: &RefCell<SimFlash>, bench: &Bench, starts: &mut Vec<u64>) -> Result<(), Halt> {
    starts.push(flash.borrow().operations());
    download(flash, &bench.new)?;
    starts.push(flash.borrow().operations());
    verify_and_mark(flash, &bench.public_key)?;
    starts.push(flash.borrow().operations());
    let state = reset(flash)?;
    if state != State::Swap {
        return Err(Halt::Broken(format!(
            "the reset after the download reported {state:?}, not Swap"
        )));
    }
    if running(flash, bench) != Ok(Running::New) {
        return Err(Halt::Broken(format!(
            "after the swap: {:?}",
            running(flash, bench)
        )));
    }
    starts.push(flash.borrow().operations());
    // The new application sees it was swapped in, passes its self-test and confirms.
    let state = app_state(flash)?;
    if state != State::Swap {
        return Err(Halt::Broken(format!(
            "the new application sees {state:?}, not Swap"
        )));
    }
    confirm(flash)?;
    Ok(())
}

/// The first part of an update whose new image never confirms itself: download, mark, swap.
fn update_unconfirmed(flash: &RefCell<SimFlash>, bench: &Bench) -> Result<(), Halt> {
    download(flash, &bench.new)?;
    verify_and_mark(flash, &bench.public_key)?;
    let state = reset(flash)?;
    if state != State::Swap || running(flash, bench) != Ok(Running::New) {
        return Err(Halt::Broken(format!(
            "the swap ended with {state:?}, {:?}",
            running(flash, bench)
        )));
    }
    Ok(())
}

/// Checks that a power cut stopped the ECU, and powers it again.
fn power_cycle(flash: &RefCell<SimFlash>, outcome: Result<(), Halt>) -> Result<(), String> {
    let mut flash = flash.borrow_mut();
    if flash.is_powered() {
        let ended = match &outcome {
            Ok(()) => "success".to_string(),
            Err(halt) => halt.to_string(),
        };
        return Err(format!(
            "the armed cut never happened; the run ended with {ended}"
        ));
    }
    if flash.last_error() != Some(&FlashError::PowerLost) {
        return Err(format!(
            "the run stopped on {:?}, not on the power cut",
            flash.last_error()
        ));
    }
    assert!(outcome.is_err(), "an interrupted run cannot succeed");
    flash.restore_power();
    Ok(())
}

/// A reset after which nothing is pending: the bootloader must not touch the flash, and the
/// image must stay.
fn quiet_reset(
    flash: &RefCell<SimFlash>,
    bench: &Bench,
    expected: Running,
) -> Result<State, String> {
    let before = flash.borrow().operations();
    let state = reset(flash).map_err(|e| format!("settled reset failed: {e:?}"))?;
    let ops = flash.borrow().operations() - before;
    if ops != 0 {
        return Err(format!(
            "a reset with nothing pending did {ops} flash operations"
        ));
    }
    let now = running(flash, bench)?;
    if now != expected {
        return Err(format!(
            "a reset with nothing pending switched from {expected:?} to {now:?}"
        ));
    }
    Ok(state)
}

/// What one cut run of the update ended with.
#[derive(Debug, Default)]
struct Tally {
    cut_points: usize,
    old: usize,
    new: usize,
    /// Runs where the new image ended running with embassy-boot's state `Revert`.
    new_with_revert_state: usize,
    /// Runs where the old image ran with state `Revert` before the retry.
    old_with_revert_state: usize,
    /// Per phase: cut points, first boot on old, first boot on new.
    per_phase: [[usize; 3]; 4],
    /// Boots of the old image while a swap was still pending.
    old_with_swap_pending: usize,
    /// Runs worth a look: where the state ended `Revert`, or a word was programmed twice.
    notes: Vec<String>,
    failures: Vec<String>,
}

impl Tally {
    fn count(&mut self, run: &UpdateRun, phase: usize) {
        if run.first == Running::Old {
            self.old += 1;
            self.per_phase[phase][1] += 1;
        } else {
            self.new += 1;
            self.per_phase[phase][2] += 1;
        }
        match (run.first, &run.first_state) {
            (Running::New, State::Revert) => self.new_with_revert_state += 1,
            (Running::Old, State::Revert) => self.old_with_revert_state += 1,
            _ => {}
        }
        self.old_with_swap_pending += run.old_with_swap_pending;
    }
}

/// How one cut run of the update went on after the power came back.
#[derive(Debug)]
struct UpdateRun {
    /// The image of the first boot after the cut.
    first: Running,
    /// The state the application read at that first boot.
    first_state: State,
    /// Boots of the old image while a swap or revert was still pending (state Swap).
    old_with_swap_pending: usize,
    /// Words programmed over non-erased ones during the whole run.
    reprogrammed: u64,
}

/// Power cut at operation `k` of the update; then the life of the ECU goes on: resets
/// (each checked), the new image confirming itself when it sees Swap, the old image retrying
/// the update when it runs with nothing pending.
fn cut_run_update(seed: u64, k: u64, bench: &Bench) -> Result<UpdateRun, String> {
    let flash = factory(seed, bench);
    flash.borrow_mut().cut_power_at(k);
    let outcome = update(&flash, bench, &mut Vec::new());
    power_cycle(&flash, outcome)?;

    let mut first = None;
    let mut old_with_swap_pending = 0;
    for _ in 0..3 {
        // Power is back: the bootloader runs, then the image in the active slot.
        let boot_state = reset(&flash).map_err(|e| {
            format!(
                "the bootloader failed after power returned: {e:?} ({:?})",
                flash.borrow().last_error()
            )
        })?;
        let now = running(&flash, bench)
            .map_err(|e| format!("boot after the cut ({boot_state:?}): {e}"))?;
        let state = app_state(&flash).map_err(|e| format!("reading the state: {e:?}"))?;
        let done = match (now, &state) {
            // The new image was swapped in but not confirmed yet: it passes its self-test.
            (Running::New, State::Swap) => {
                confirm(&flash).map_err(|e| format!("the new image cannot confirm: {e:?}"))?;
                true
            }
            (Running::New, State::Boot | State::Revert) => true,
            // The update did not get through: the old image runs with nothing pending, and
            // the tester retries the whole update, which must succeed.
            (Running::Old, State::Boot | State::Revert) => {
                quiet_reset(&flash, bench, Running::Old)?;
                update(&flash, bench, &mut Vec::new())
                    .map_err(|e| format!("the retry failed: {e}"))?;
                true
            }
            // The old image runs while the bootloader still has a swap or revert to finish
            // (it cannot take an update in this state): it just runs until the next reset.
            (Running::Old, State::Swap) => {
                old_with_swap_pending += 1;
                false
            }
            (image, state) => return Err(format!("{image:?} image running with state {state:?}")),
        };
        if first.is_none() {
            first = Some((now, state));
        }
        if done {
            let final_state = quiet_reset(&flash, bench, Running::New)?;
            let app_final = app_state(&flash).map_err(|e| format!("reading the state: {e:?}"))?;
            if !matches!(app_final, State::Boot | State::Revert) || final_state != app_final {
                return Err(format!(
                    "ended with the bootloader seeing {final_state:?} and the application {app_final:?}"
                ));
            }
            let (first, first_state) = first.take().ok_or("no boot recorded")?;
            let reprogrammed = flash.borrow().stats().reprogrammed_words;
            return Ok(UpdateRun {
                first,
                first_state,
                old_with_swap_pending,
                reprogrammed,
            });
        }
    }
    Err("the ECU had not settled after three resets".to_string())
}

/// Runs the update once without a cut (returning its operation count and the phase starts),
/// then once per operation with the power cut there.
fn sweep_update(seed: u64, bench: &Bench) -> (u64, Tally) {
    let flash = factory(seed, bench);
    flash.borrow_mut().record_trace(true);
    let start = flash.borrow().operations();
    let mut starts = Vec::new();
    update(&flash, bench, &mut starts)
        .unwrap_or_else(|e| panic!("the update without a cut fails: {e}"));
    let total = flash.borrow().operations() - start;
    let trace = flash.borrow().trace().to_vec();
    assert_eq!(trace.len() as u64, total);
    assert_eq!(quiet_reset(&flash, bench, Running::New), Ok(State::Boot));

    let mut tally = Tally::default();
    for k in 0..total {
        let phase = starts
            .iter()
            .rposition(|&s| s - start <= k)
            .expect("phase of the operation");
        tally.cut_points += 1;
        tally.per_phase[phase][0] += 1;
        match cut_run_update(seed, k, bench) {
            Ok(run) => {
                tally.count(&run, phase);
                if run.first_state == State::Revert
                    || run.reprogrammed > 0
                    || run.old_with_swap_pending > 0
                {
                    tally.notes.push(format!(
                        "cut at operation {k} ({}): first boot on the {:?} image with state {:?}; \
                         {} boot(s) of the old image with a swap pending; {} word(s) programmed over non-erased ones",
                        trace[k as usize], run.first, run.first_state, run.old_with_swap_pending, run.reprogrammed
                    ));
                }
            }
            Err(why) => tally.failures.push(format!(
                "seed {seed:#x}, cut at operation {k} ({}, during {}): {why}",
                trace[k as usize], PHASES[phase]
            )),
        }
    }
    (total, tally)
}

/// Operations of an uninterrupted update, from the map: the DFU erases the image needs, one write per
/// TransferData block, the mark (validity word; the state erase, which erases the other
/// state copy and writes its header; magic), the swap (per copied page: erase, one write per
/// swap buffer, a progress word; two copies for the one-page slot), and the confirmation
/// (as the mark).
fn expected_update_operations() -> u64 {
    let dfu_erases = (UPDATE_LEN + SIGNATURE_LEN).div_ceil(SLOT_ERASE_SIZE as usize) as u64;
    let blocks = (UPDATE_LEN + SIGNATURE_LEN).div_ceil(TRANSFER_BLOCK) as u64;
    let copy = 1 + u64::from(BOOT_PAGE_SIZE) / BOOT_SWAP_BUFFER_SIZE as u64 + 1;
    let pages = u64::from(ACTIVE.size / BOOT_PAGE_SIZE);
    dfu_erases + blocks + 4 + 2 * pages * copy + 4
}

fn report(tally: &Tally) -> String {
    let mut text = String::new();
    for (phase, [cuts, old, new]) in PHASES.iter().zip(tally.per_phase) {
        let _ = writeln!(
            text,
            "  {phase}: {cuts} cut points, {old} on the old image, {new} on the new"
        );
    }
    let _ = writeln!(
        text,
        "  new image left with state Revert: {}; old image running with state Revert before the retry: {}; \
         boots of the old image with a swap pending: {}",
        tally.new_with_revert_state, tally.old_with_revert_state, tally.old_with_swap_pending
    );
    for note in &tally.notes {
        let _ = writeln!(text, "  {note}");
    }
    text
}

#[test]
fn update_survives_a_power_cut_at_every_operation() {
    let bench = Bench::new();
    let (total, tally) = sweep_update(FLASH_SEED, &bench);
    println!(
        "power-cut test: {} cut points tried, {} ended on the old image, {} on the new",
        tally.cut_points, tally.old, tally.new
    );
    print!("{}", report(&tally));
    assert!(
        tally.failures.is_empty(),
        "cut points that broke the invariant:\n{}",
        tally.failures.join("\n")
    );
    assert_eq!(total, expected_update_operations());
    assert_eq!(
        total, 94,
        "1 DFU erase + 17 blocks + 4 (mark) + 68 (swap) + 4 (confirm)"
    );
    assert_eq!(tally.cut_points as u64, total);
    assert_eq!(tally.old + tally.new, tally.cut_points);
    assert!(tally.old > 0 && tally.new > 0, "both outcomes occur");
}

/// The same sweeps with other seeds, so interrupted erases and writes leave other mixtures
/// (which words of the state sector read old, erased or garbage; where a write stops).
#[test]
fn update_and_revert_survive_power_cuts_with_other_seeds() {
    let bench = Bench::new();
    let mut failures = Vec::new();
    let (mut runs, mut old, mut new) = (0, 0, 0);
    let (mut new_revert, mut old_revert) = (0, 0);
    for seed in 1..=6 {
        let (total, tally) = sweep_update(seed, &bench);
        assert_eq!(total, expected_update_operations());
        runs += tally.cut_points;
        old += tally.old;
        new += tally.new;
        new_revert += tally.new_with_revert_state;
        old_revert += tally.old_with_revert_state;
        failures.extend(tally.failures);
    }
    println!(
        "power-cut test, seeds 1..=6: {runs} runs, {old} ended on the old image, {new} on the new; \
         new image with state Revert: {new_revert}, old image with state Revert: {old_revert}"
    );
    let (mut runs, mut old, mut new) = (0, 0, 0);
    for seed in 1..=6 {
        let (_, tally) = sweep_revert(seed, &bench);
        runs += tally.cut_points;
        old += tally.old;
        new += tally.new;
        print_revert_notes(&tally);
        failures.extend(tally.failures);
    }
    println!("revert power-cut test, seeds 1..=6: {runs} runs, {old} ended on the old image, {new} on the new");
    assert!(
        failures.is_empty(),
        "cut points that broke the invariant:\n{}",
        failures.join("\n")
    );
}

/// What the cut runs of a revert ended with.
#[derive(Debug, Default)]
struct RevertTally {
    cut_points: usize,
    /// First boot after the cut on the old image.
    old: usize,
    /// First boot after the cut on the (unconfirmed) new image.
    new: usize,
    /// Runs where the unconfirmed image booted again after the cut, before the revert.
    unconfirmed_booted_again: Vec<String>,
    /// Runs that ended with the unconfirmed image running and nothing pending: the rollback
    /// was lost (see `state_erase_cuts_with_many_seeds`). Must stay empty.
    kept_unconfirmed: Vec<String>,
    /// Boots of the old image while a swap or revert was still pending.
    old_with_swap_pending: usize,
    failures: Vec<String>,
}

/// An ECU whose new image was swapped in and runs, but fails its self-test: it never calls
/// mark_booted, so the next reset must revert.
fn swapped_unconfirmed(seed: u64, bench: &Bench) -> RefCell<SimFlash> {
    let flash = factory(seed, bench);
    update_unconfirmed(&flash, bench)
        .unwrap_or_else(|e| panic!("download, mark and swap without a cut fail: {e}"));
    assert_eq!(app_state(&flash).expect("state"), State::Swap);
    flash
}

/// How one cut run of a revert went on after the power came back.
#[derive(Debug)]
struct RevertRun {
    /// The image of the first boot after the cut.
    first: Running,
    /// Boots of the unconfirmed new image after the cut.
    unconfirmed_boots: usize,
    /// Boots of the old image while a swap or revert was still pending.
    old_with_swap_pending: usize,
    /// Whether it ended with the unconfirmed image running and nothing pending.
    kept_unconfirmed: bool,
}

/// Power cut at operation `k` of the revert; then resets until the ECU settles (the new
/// image never confirms itself), and a next update from the old image must succeed.
fn cut_run_revert(seed: u64, k: u64, bench: &Bench) -> Result<RevertRun, String> {
    let flash = swapped_unconfirmed(seed, bench);
    flash.borrow_mut().cut_power_at(k);
    let outcome = reset(&flash).map(|_| ()).map_err(Halt::Boot);
    power_cycle(&flash, outcome)?;
    let mut first = None;
    let (mut unconfirmed_boots, mut old_with_swap_pending) = (0, 0);
    for _ in 0..4 {
        reset(&flash).map_err(|e| format!("reset after the cut failed: {e:?}"))?;
        let now = running(&flash, bench)?;
        let first = *first.get_or_insert(now);
        let state = app_state(&flash).map_err(|e| format!("state: {e:?}"))?;
        let run = |kept_unconfirmed| RevertRun {
            first,
            unconfirmed_boots,
            old_with_swap_pending,
            kept_unconfirmed,
        };
        match (now, state) {
            // The unconfirmed image runs again; it fails its self-test again.
            (Running::New, State::Swap) => unconfirmed_boots += 1,
            // The old image runs while a swap or revert is still pending.
            (Running::Old, State::Swap) => old_with_swap_pending += 1,
            (Running::Old, State::Revert | State::Boot) => {
                quiet_reset(&flash, bench, Running::Old)?;
                update(&flash, bench, &mut Vec::new())
                    .map_err(|e| format!("the next update failed: {e}"))?;
                quiet_reset(&flash, bench, Running::New)?;
                return Ok(run(false));
            }
            // The unconfirmed image runs and nothing will revert it any more: a complete
            // image, but the rollback is lost.
            (Running::New, State::Revert | State::Boot) => {
                quiet_reset(&flash, bench, Running::New)?;
                return Ok(run(true));
            }
            (image, state) => return Err(format!("{image:?} image running with state {state:?}")),
        }
    }
    Err("the ECU had not settled after four resets".to_string())
}

/// Runs the revert once without a cut (returning its operation count), then once per
/// operation with the power cut there.
fn sweep_revert(seed: u64, bench: &Bench) -> (u64, RevertTally) {
    let flash = swapped_unconfirmed(seed, bench);
    flash.borrow_mut().record_trace(true);
    let before = flash.borrow().operations();
    // prepare_boot returns the state it found (Swap) even though it reverted; the
    // application then reads Revert.
    assert_eq!(reset(&flash), Ok(State::Swap));
    let total = flash.borrow().operations() - before;
    let trace = flash.borrow().trace().to_vec();
    assert_eq!(running(&flash, bench), Ok(Running::Old));
    assert_eq!(app_state(&flash).expect("state"), State::Revert);
    assert_eq!(quiet_reset(&flash, bench, Running::Old), Ok(State::Revert));

    let mut tally = RevertTally::default();
    for k in 0..total {
        tally.cut_points += 1;
        let op = trace[k as usize];
        match cut_run_revert(seed, k, bench) {
            Ok(run) => {
                if run.first == Running::Old {
                    tally.old += 1;
                } else {
                    tally.new += 1;
                }
                tally.old_with_swap_pending += run.old_with_swap_pending;
                let what = format!("seed {seed}, cut at revert operation {k} ({op})");
                if run.unconfirmed_boots > 0 {
                    tally.unconfirmed_booted_again.push(format!(
                        "{what}: the unconfirmed image booted {} more time(s)",
                        run.unconfirmed_boots
                    ));
                }
                if run.kept_unconfirmed {
                    let lost = format!("{what}: rollback lost, the unconfirmed image stays");
                    tally.kept_unconfirmed.push(lost.clone());
                    tally.failures.push(lost);
                }
            }
            Err(why) => tally.failures.push(format!(
                "seed {seed}, cut at revert operation {k} ({op}): {why}"
            )),
        }
    }
    (total, tally)
}

/// Whether `op` erases a copy of the persistent state (where embassy-boot's state is).
fn is_state_erase(op: &FlashOp) -> bool {
    matches!(op, FlashOp::Erase { sector } if STATE_COPIES.iter().any(|c| c.start == sector.start))
}

fn print_revert_notes(tally: &RevertTally) {
    if tally.old_with_swap_pending > 0 {
        println!(
            "  boots of the old image with a swap pending: {}",
            tally.old_with_swap_pending
        );
    }
    for note in &tally.unconfirmed_booted_again {
        println!("  {note}");
    }
    println!(
        "  rollbacks lost (unconfirmed image left with nothing pending): {}",
        tally.kept_unconfirmed.len()
    );
}

/// A new image that never confirms itself is reverted at the next reset; a cut at any
/// operation of that revert still ends on a complete image, and finally on the old one.
#[test]
fn unconfirmed_image_reverts_even_with_a_power_cut() {
    let bench = Bench::new();
    let (total, tally) = sweep_revert(FLASH_SEED, &bench);
    println!(
        "revert power-cut test: {} cut points tried, {} ended on the old image, {} on the new",
        tally.cut_points, tally.old, tally.new
    );
    print_revert_notes(&tally);
    assert!(
        tally.failures.is_empty(),
        "cut points that broke the invariant:\n{}",
        tally.failures.join("\n")
    );
    let copy = 1 + u64::from(BOOT_PAGE_SIZE) / BOOT_SWAP_BUFFER_SIZE as u64 + 1;
    assert_eq!(
        total,
        2 * copy + 4,
        "two page copies, then validity word, state copy erase and header, magic"
    );
    assert_eq!(total, 72);
    assert_eq!(tally.cut_points as u64, total);
    assert_eq!(tally.old + tally.new, tally.cut_points);
}

/// Where an interrupted erase matters most is the state: which of its words (magic, progress
/// validity, progress) read old, erased or garbage decides what the next reset does. So the
/// cut points that erase a state copy get many seeds, i.e. many such mixtures.
///
/// Over embassy-boot 0.7's single state sector this lost rollbacks: before erasing, embassy-boot
/// invalidates the progress (programs the validity word to zero) but leaves the magic word,
/// and an erase cut so that the magic still read SWAP while the validity word and an early
/// progress word read erased made the next reset swap again — after a revert, bringing the
/// unconfirmed image back with nothing left to revert it. With the two copies, the erase hits
/// the copy that is not current: the state reads exactly as before the cut, and the revert
/// completes at the next reset. Cut during the confirmation, a new image can still end with
/// state `Revert` (the invalidated progress reads "swap done"): it runs, complete.
#[test]
fn state_erase_cuts_with_many_seeds() {
    let bench = Bench::new();

    let flash = factory(FLASH_SEED, &bench);
    flash.borrow_mut().record_trace(true);
    update(&flash, &bench, &mut Vec::new())
        .unwrap_or_else(|e| panic!("the update without a cut fails: {e}"));
    let update_points: Vec<u64> = (0..)
        .zip(flash.borrow().trace())
        .filter(|(_, op)| is_state_erase(op))
        .map(|(k, _)| k)
        .collect();
    assert_eq!(
        update_points.len(),
        2,
        "the mark and the confirmation each erase a state copy once"
    );

    let flash = swapped_unconfirmed(FLASH_SEED, &bench);
    flash.borrow_mut().record_trace(true);
    reset(&flash).expect("the revert without a cut succeeds");
    let revert_points: Vec<u64> = (0..)
        .zip(flash.borrow().trace())
        .filter(|(_, op)| is_state_erase(op))
        .map(|(k, _)| k)
        .collect();
    assert_eq!(
        revert_points.len(),
        1,
        "the revert erases a state copy once"
    );

    const SEEDS: std::ops::Range<u64> = 1000..1200;
    let runs = SEEDS.end - SEEDS.start;
    let mut failures = Vec::new();
    for (what, &k) in ["mark", "confirmation"].iter().zip(&update_points) {
        let mut tally = Tally::default();
        for seed in SEEDS {
            match cut_run_update(seed, k, &bench) {
                Ok(run) => tally.count(&run, 0),
                Err(why) => failures.push(format!("seed {seed}, update operation {k}: {why}")),
            }
        }
        println!(
            "state erase cut during the {what} (operation {k}), {runs} seeds: first boot on the old image {}, on the new {}; \
             new image with state Revert {}, old image with state Revert {}, boots of the old image with a swap pending {}",
            tally.old, tally.new, tally.new_with_revert_state, tally.old_with_revert_state, tally.old_with_swap_pending
        );
    }

    let mut tally = RevertTally::default();
    let k = revert_points[0];
    for seed in SEEDS {
        match cut_run_revert(seed, k, &bench) {
            Ok(run) => {
                if run.first == Running::Old {
                    tally.old += 1;
                } else {
                    tally.new += 1;
                }
                tally.old_with_swap_pending += run.old_with_swap_pending;
                if run.unconfirmed_boots > 0 {
                    tally.unconfirmed_booted_again.push(format!("seed {seed}"));
                }
                if run.kept_unconfirmed {
                    tally.kept_unconfirmed.push(format!("seed {seed}"));
                }
            }
            Err(why) => failures.push(format!("seed {seed}, revert operation {k}: {why}")),
        }
    }
    println!(
        "state erase cut during the revert (operation {k}), {runs} seeds: first boot on the old image {}, on the \
         unconfirmed new one {}; the unconfirmed image booted again in {} runs; boots of the old image with a swap \
         pending {}",
        tally.old,
        tally.new,
        tally.unconfirmed_booted_again.len(),
        tally.old_with_swap_pending
    );
    println!(
        "  rollbacks lost (the unconfirmed image left with nothing pending): {} of {runs} runs",
        tally.kept_unconfirmed.len(),
    );
    assert!(
        failures.is_empty(),
        "runs that broke the invariant:\n{}",
        failures.join("\n")
    );
    assert_eq!(
        tally.kept_unconfirmed,
        Vec::<String>::new(),
        "a cut in a state erase must not lose the rollback"
    );
}

/// The simulated busy time of an uninterrupted update of a 64 KiB image (+ its signature),
/// against the datasheet arithmetic: 16 µs per word, 250 ms per 16 KiB sector, 1 s per
/// 128 KiB sector (DS10693, typ., x32).
#[test]
fn update_busy_time_follows_the_datasheet() {
    let bench = Bench::new();
    let flash = factory(FLASH_SEED, &bench);
    let word = Duration::from_micros(16);
    let erase_16k = Duration::from_millis(250);
    let erase_128k = Duration::from_millis(1000);
    let busy = || flash.borrow().total_busy();
    let image_words = (UPDATE_LEN + SIGNATURE_LEN) as u32 / 4; // 16 400

    let t0 = busy();
    download(&flash, &bench.new).expect("download");
    let download_time = busy() - t0;
    // The one 128 KiB sector the image needs, then the blocks.
    assert_eq!(download_time, erase_128k + word * image_words);
    assert_eq!(download_time, Duration::from_micros(1_262_400));

    let t0 = busy();
    verify_and_mark(&flash, &bench.public_key).expect("mark");
    let mark_time = busy() - t0;
    // Validity word, erase of the other state copy and its 3-word header, magic word.
    assert_eq!(mark_time, erase_16k + 5 * word);

    let t0 = busy();
    assert_eq!(reset(&flash), Ok(State::Swap));
    let swap_time = busy() - t0;
    // Two page copies: erase a 128 KiB sector, program its 32 768 words, one progress word.
    assert_eq!(swap_time, 2 * (erase_128k + word * (32_768 + 1)));
    assert_eq!(swap_time, Duration::from_micros(3_048_608));

    let t0 = busy();
    confirm(&flash).expect("confirm");
    let confirm_time = busy() - t0;
    assert_eq!(confirm_time, erase_16k + 5 * word);

    let total = download_time + mark_time + swap_time + confirm_time;
    assert_eq!(total, Duration::from_micros(4_811_168));
    println!(
        "64 KiB update, simulated flash busy time: download {download_time:?}, mark {mark_time:?}, \
         swap at reset {swap_time:?}, confirm {confirm_time:?}, total {total:?}"
    );
}
