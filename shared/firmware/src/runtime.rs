//! The control loop every ECU firmware runs, generic over the ECU's logic
//! ([`EcuLogic`]) and its board ([`Io`]): the board reads sensors and drives actuators,
//! the logic decides, and this module moves data between them, CAN1 and the clock.
//!
//! Tasks (one thread-mode executor):
//! - the control loop, in [`run`]: owns the logic (no mutex). Runs `step` on a ticker every
//!   `STEP_PERIOD_US` (reading sensors, driving outputs, feeding the watchdog) and
//!   `on_frame` as soon as a frame arrives; after either, queues every frame
//!   `poll_transmit` hands out;
//! - CAN1 → RX queue, TX queue → CAN1 mailboxes, and the error monitor ([`can_io`]).

use autoplug_ecu::{EcuLogic, Instant};
use autoplug_uds::{DiagNode, DEV_SECURITY_SECRET};
use embassy_boot::State;
use embassy_executor::Spawner;
use embassy_futures::select::{select3, Either3};
use embassy_stm32::can::{Can, CanRx, CanTx};
use embassy_stm32::flash::Flash;
use embassy_stm32::pac;
use embassy_stm32::peripherals::{FLASH, IWDG};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::Peri;
use embassy_time::{Duration, Ticker, Timer};

use crate::can_io::{self, RxQueue, TxQueue};
use crate::diag::{EcuFlash, FirmwareBackend};
use crate::entropy;
use crate::reset::{ResetCause, ResetFlags};

static RX_QUEUE: RxQueue = RxQueue::new();
static TX_QUEUE: TxQueue = TxQueue::new();

/// The independent watchdog's timeout, in control periods: a loop that misses this many
/// steps in a row is stuck, and the ECU resets into its power-up state.
pub const WATCHDOG_TIMEOUT_PERIODS: u64 = 10;

/// How often the DTCs are checked for changes (and logged if they changed).
const DTC_LOG_PERIOD_US: u64 = 1_000_000;

/// A board: the ECU's sensors and actuators, as the logic sees them.
pub trait Io<E: EcuLogic> {
    /// Reads every sensor and switch.
    fn read(&mut self) -> E::Sensors;
    /// Drives every actuator.
    fn write(&mut self, actuators: &E::Actuators);
}

/// What every board hands to [`run`] besides its [`Io`].
pub struct Platform {
    /// CAN1 on the board's CAN pins, not yet configured.
    pub can: Can<'static>,
    /// The independent watchdog, not yet started.
    pub watchdog: Peri<'static, IWDG>,
    /// The flash controller, for firmware upgrades over CAN.
    pub flash: Peri<'static, FLASH>,
}

/// How often the diagnostic stack is polled while it has work (a transfer, a session):
/// ISO-TP timing and the programming slices want about a millisecond.
const DIAG_POLL_US: u64 = 1_000;

/// Control steps (with frames sent) before a freshly swapped-in image confirms itself.
const SELF_TEST_STEPS: u32 = 10;

/// Time for the last response to leave before a reset the tester asked for.
const RESET_DRAIN_MS: u64 = 10;

/// The logic's clock: microseconds since power-up.
pub fn now() -> Instant {
    Instant::from_micros(embassy_time::Instant::now().as_micros())
}

/// Runs an ECU: logs why it reset, brings CAN1 onto the bus with the node's acceptance
/// filters, starts the CAN tasks, builds the logic with `new_ecu` (given the time) and
/// runs the control loop forever. The board's outputs should be at their safe (zero)
/// state when this is called; the first step sets them.
pub async fn run<E, B>(
    spawner: Spawner,
    platform: Platform,
    mut board: B,
    new_ecu: impl FnOnce(Instant) -> E,
) -> !
where
    E: EcuLogic,
    E::Sensors: defmt::Format,
    E::Actuators: defmt::Format,
    B: Io<E>,
{
    let Platform {
        mut can,
        watchdog,
        flash,
    } = platform;
    defmt::info!(
        "{} ECU (node {=?}), reset cause: {}",
        E::NODE,
        E::NODE.diag_node_number(),
        take_reset_cause()
    );

    can_io::start(&mut can, E::NODE).await;
    let (tx, rx) = can.split();
    // defmt's unwrap, not `expect`: the latter's message formatting would pull core::fmt
    // into the image (see `fault`).
    spawner.spawn(defmt::unwrap!(can_rx(rx)));
    spawner.spawn(defmt::unwrap!(can_tx(tx)));
    spawner.spawn(defmt::unwrap!(can_monitor()));

    let layout = Flash::new_blocking(flash).into_blocking_regions();
    let mut ecu_flash = EcuFlash::new(layout.bank1_region1, layout.bank1_region3);
    let mut unconfirmed = ecu_flash.boot_state() == State::Swap;
    let mut diag = defmt::unwrap!(DiagNode::new(E::NODE, DEV_SECURITY_SECRET, now()));
    let mut seeds = entropy::seed_source(ecu_flash.next_seed_epoch());

    let timeout_us = WATCHDOG_TIMEOUT_PERIODS * E::STEP_PERIOD_US;
    let mut watchdog = IndependentWatchdog::new(watchdog, timeout_us as u32);
    let mut ecu = new_ecu(now());
    let mut ticker = Ticker::every(Duration::from_micros(E::STEP_PERIOD_US));
    let mut diag_ticker = Ticker::every(Duration::from_micros(DIAG_POLL_US));
    let dtc_log_every_steps = (DTC_LOG_PERIOD_US / E::STEP_PERIOD_US).max(1) as u32;
    let mut steps: u32 = 0;
    let mut sent: u32 = 0;
    let mut logged_dtcs = None;
    watchdog.unleash();
    defmt::info!(
        "control loop every {} us, watchdog {} us",
        E::STEP_PERIOD_US,
        timeout_us
    );
    // The backend of one diagnostic call, from the loop's state.
    macro_rules! backend {
        () => {
            FirmwareBackend {
                node: E::NODE,
                flash: &mut ecu_flash,
                own_motion: ecu.own_sensors_show_motion(),
                dtcs: ecu.dtcs_mut(),
                seeds: &mut seeds,
            }
        };
    }
    loop {
        match select3(ticker.next(), RX_QUEUE.receive(), diag_ticker.next()).await {
            Either3::First(()) => {
                let sensors = board.read();
                let actuators = ecu.step(now(), &sensors);
                board.write(&actuators);
                watchdog.pet();
                defmt::trace!("step: {} -> {}", sensors, actuators);
                steps = steps.wrapping_add(1);
                if steps % dtc_log_every_steps == 0 {
                    log_dtcs_if_changed(ecu.dtcs(), &mut logged_dtcs);
                }
                // The self-test of a new image: CAN up, the control loop running, frames
                // going out. Only then does it keep itself (else the next reset reverts).
                if unconfirmed && steps >= SELF_TEST_STEPS && sent > 0 {
                    unconfirmed = !ecu_flash.confirm();
                    if !unconfirmed {
                        defmt::info!("self-test passed: this image is confirmed");
                    }
                }
            }
            Either3::Second(frame) => {
                entropy::note_frame(&mut seeds);
                if diag.accepts(frame.id()) {
                    diag.on_frame(now(), &frame, &mut backend!());
                } else {
                    diag.observe(now(), &frame);
                    if diag.server().normal_rx_enabled() {
                        ecu.on_frame(now(), &frame);
                    }
                }
            }
            Either3::Third(()) => {
                if !diag.quiescent() {
                    diag.poll(now(), &mut backend!());
                }
            }
        }
        let tx_enabled = diag.server().normal_tx_enabled();
        while let Some(frame) = ecu.poll_transmit(now()) {
            diag.note_sent(now(), &frame);
            if tx_enabled {
                can_io::queue_for_transmit(&TX_QUEUE, frame);
                sent = sent.wrapping_add(1);
            }
        }
        while let Some(frame) = diag.poll_transmit(now()) {
            can_io::queue_for_transmit(&TX_QUEUE, frame);
            diag.confirm_transmit(now());
        }
        if let Some(kind) = diag.take_reset() {
            defmt::warn!("reset ({}) requested by the tester", kind);
            Timer::after_millis(RESET_DRAIN_MS).await;
            cortex_m::peripheral::SCB::sys_reset();
        }
    }
    // `can` was split, not dropped: dropping the driver would reset CAN1 under the RX and
    // TX halves, and `run` never returns.
}

#[embassy_executor::task]
async fn can_rx(rx: CanRx<'static>) {
    can_io::receive(rx, &RX_QUEUE).await
}

#[embassy_executor::task]
async fn can_tx(tx: CanTx<'static>) {
    can_io::transmit(tx, &TX_QUEUE).await
}

#[embassy_executor::task]
async fn can_monitor() {
    can_io::monitor().await
}

/// Reads the reset flags and clears them, so the next reset's flags stand alone.
fn take_reset_cause() -> ResetCause {
    let csr = pac::RCC.csr().read();
    let flags = ResetFlags {
        low_power: csr.lpwrrstf(),
        window_watchdog: csr.wwdgrstf(),
        independent_watchdog: csr.wdgrstf(),
        software: csr.sftrstf(),
        power_on: csr.porrstf(),
        brown_out: csr.borrstf(),
        pin: csr.padrstf(),
    };
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    ResetCause::from_flags(flags)
}

/// Logs every DTC record when the set of records or their status changed since the last
/// log (`logged`: a summary of what was logged).
fn log_dtcs_if_changed(dtcs: &autoplug_ecu::Dtcs, logged: &mut Option<(usize, u32, u32)>) {
    let summary = dtcs
        .records()
        .fold((0usize, 0u32, dtcs.dropped()), |(n, sum, dropped), r| {
            (
                n + 1,
                sum.wrapping_add(r.dtc.to_u24() ^ u32::from(r.status) << 24)
                    .wrapping_add(u32::from(r.occurrences)),
                dropped,
            )
        });
    if *logged == Some(summary) {
        return;
    }
    *logged = Some(summary);
    let (count, _, dropped) = summary;
    defmt::info!("DTCs: {} stored ({} dropped)", count, dropped);
    for record in dtcs.records() {
        if record.is_active() {
            defmt::error!("DTC {}", record);
        } else {
            defmt::info!("DTC {}", record);
        }
    }
}
