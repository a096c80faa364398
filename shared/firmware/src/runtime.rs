//! The control loop every ECU firmware runs, generic over the ECU's logic
//! ([`EcuLogic`]) and its board ([`Io`]): the board reads sensors and drives actuators,
//! the logic decides, and this module moves data between them, CAN1 and the clock.
//!
//! Tasks (one thread-mode executor):
//! - the control loop, in [`run`]: owns the logic (no mutex). Runs `step` on a ticker every
//!   `STEP_PERIOD_US` (reading sensors, driving outputs, feeding the watchdog) and
//!   `on_frame` as soon as a frame arrives (then `step` at once if the logic asks for it,
//!   the ticker restarting from there); after either, queues every frame `poll_transmit`
//!   hands out;
//! - CAN1 → RX queue, TX queue → CAN1 mailboxes, and the error monitor ([`can_io`]).

use autoplug_can::Frame;
use autoplug_ecu::{EcuLogic, Instant};
use autoplug_flash::ab::BootState;
use autoplug_uds::security::SeedSource;
use autoplug_uds::{DiagNode, ResetKind, DEV_SECURITY_SECRET};
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

/// Control steps (with frames sent) before a newly started image on trial confirms itself.
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
    board: B,
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

    let timeout_us = WATCHDOG_TIMEOUT_PERIODS * E::STEP_PERIOD_US;
    let mut state = LoopState::start(board, flash, watchdog, timeout_us, new_ecu);
    let mut ticker = Ticker::every(Duration::from_micros(E::STEP_PERIOD_US));
    let mut diag_ticker = Ticker::every(Duration::from_micros(DIAG_POLL_US));
    defmt::info!(
        "control loop every {} us, watchdog {} us",
        E::STEP_PERIOD_US,
        timeout_us
    );
    // The diagnostic stack's 1 ms wake-ups are taken only while it has work: idle (it is,
    // nearly always) they would be most of what the MCU does, half the instructions of a
    // drive cycle measured on the emulated car.
    let mut diag_idle = true;
    loop {
        let diag_wake = async {
            if diag_idle {
                core::future::pending::<()>().await
            } else {
                diag_ticker.next().await
            }
        };
        match select3(ticker.next(), RX_QUEUE.receive(), diag_wake).await {
            Either3::First(()) => state.control_step(),
            Either3::Second(frame) => {
                state.received(&frame);
                // A command that must act at once (the brake pedal pressed): step now and
                // count the next period from here.
                if state.ecu.step_requested() {
                    state.control_step();
                    ticker.reset();
                }
            }
            Either3::Third(()) => state.diag_poll(),
        }
        if let Some(kind) = state.transmit() {
            defmt::warn!("reset ({}) requested by the tester", kind);
            Timer::after_millis(RESET_DRAIN_MS).await;
            cortex_m::peripheral::SCB::sys_reset();
        }
        let idle = state.diag.quiescent();
        if diag_idle && !idle {
            // Work has come (a request): the first poll a period from now, not a burst
            // for every period the ticker slept through.
            diag_ticker.reset();
        }
        diag_idle = idle;
    }
    // `can` was split, not dropped: dropping the driver would reset CAN1 under the RX and
    // TX halves, and `run` never returns.
}

/// Everything the control loop owns. Its handlers are functions of their own, called
/// from the async loop, rather than code inlined into the loop's future: there every
/// access to the logic's state goes through the future's frame, and measured with
/// scripts/firmware-size that costs about 0.8 KB of flash per firmware.
struct LoopState<E, B> {
    ecu: E,
    board: B,
    diag: DiagNode,
    ecu_flash: EcuFlash,
    seeds: SeedSource,
    watchdog: IndependentWatchdog<'static, IWDG>,
    /// A new image started on trial that has not passed its self-test yet.
    unconfirmed: bool,
    dtc_log_every_steps: u32,
    steps: u32,
    sent: u32,
    logged_dtcs: Option<(usize, u32, u32)>,
    /// Since when a long operation's next step has waited for the transmit path to empty.
    resume_held_since: Option<Instant>,
}

/// The backend of one diagnostic call, from the loop's state (a macro, not a method, so
/// that it borrows the fields it needs and leaves `diag` free).
macro_rules! backend {
    ($state:expr) => {
        FirmwareBackend {
            node: E::NODE,
            flash: &mut $state.ecu_flash,
            own_motion: $state.ecu.own_sensors_show_motion(),
            dtcs: $state.ecu.dtcs_mut(),
            seeds: &mut $state.seeds,
        }
    };
}

impl<E, B> LoopState<E, B>
where
    E: EcuLogic,
    E::Sensors: defmt::Format,
    E::Actuators: defmt::Format,
    B: Io<E>,
{
    /// Builds the loop's state: the flash (and whether this image still has to confirm
    /// itself), the diagnostic stack, the seed source, the logic (given the time), and
    /// the watchdog, started. Out of line, so the state is built in place rather than
    /// moved piece by piece into the loop's future.
    #[inline(never)]
    fn start(
        board: B,
        flash: Peri<'static, FLASH>,
        watchdog: Peri<'static, IWDG>,
        watchdog_timeout_us: u64,
        new_ecu: impl FnOnce(Instant) -> E,
    ) -> Self {
        let layout = Flash::new_blocking(flash).into_blocking_regions();
        let ecu_flash = EcuFlash::new(layout.bank1_region1, layout.bank1_region3);
        let unconfirmed = ecu_flash.boot_state() == BootState::Trial;
        // defmt's unwrap, not `expect` (see above).
        let diag = defmt::unwrap!(DiagNode::new(E::NODE, DEV_SECURITY_SECRET, now()));
        let seeds = entropy::seed_source(ecu_flash.next_seed_epoch());
        let mut watchdog = IndependentWatchdog::new(watchdog, watchdog_timeout_us as u32);
        let ecu = new_ecu(now());
        watchdog.unleash();
        crate::diag::feed_watchdog_when_loaded();
        Self {
            ecu,
            board,
            diag,
            ecu_flash,
            seeds,
            watchdog,
            unconfirmed,
            dtc_log_every_steps: (DTC_LOG_PERIOD_US / E::STEP_PERIOD_US).max(1) as u32,
            steps: 0,
            sent: 0,
            logged_dtcs: None,
            resume_held_since: None,
        }
    }

    /// One control period: sensors, logic, actuators, the watchdog.
    #[inline(never)]
    fn control_step(&mut self) {
        let sensors = self.board.read();
        let actuators = self.ecu.step(now(), &sensors);
        self.board.write(&actuators);
        self.watchdog.pet();
        defmt::trace!("step: {} -> {}", sensors, actuators);
        self.steps = self.steps.wrapping_add(1);
        if self.steps % self.dtc_log_every_steps == 0 {
            log_dtcs_if_changed(self.ecu.dtcs(), &mut self.logged_dtcs);
        }
        // The self-test of a new image: CAN up, the control loop running, frames going
        // out. Only then does it keep itself (else the next reset reverts).
        if self.unconfirmed && self.steps >= SELF_TEST_STEPS && self.sent > 0 {
            self.unconfirmed = !self.ecu_flash.confirm();
            if !self.unconfirmed {
                defmt::info!("self-test passed: this image is confirmed");
            }
        }
    }

    /// A frame from the bus: to the diagnostic stack if it is addressed to it, else to the
    /// logic (unless the tester has turned normal reception off).
    #[inline(never)]
    fn received(&mut self, frame: &Frame) {
        entropy::note_frame(&mut self.seeds);
        if self.diag.accepts(frame.id()) {
            self.diag.on_frame(now(), frame, &mut backend!(self));
        } else {
            self.diag.observe(now(), frame);
            if self.diag.server().normal_rx_enabled() {
                self.ecu.on_frame(now(), frame);
            }
        }
    }

    /// The diagnostic stack's timers, while it has work.
    ///
    /// The stack takes a frame as sent when it is queued (see `transmit`), but a long
    /// operation's next step, a sector erase, stalls the core for a second, and the 0x78
    /// before it must be on the bus by then. When the 1 ms tick fell due while the loop
    /// handled the request, the next `select3` returned at once without yielding, the
    /// erase began before the transmit task had run, and the 0x78 came after the tester's
    /// P2 (on the emulated car, for requests ending in 50 of the tick's 1000 µs:
    /// `firmware_update.rs`). So that step waits until the transmit path is empty, at most
    /// the P2server the ECU announces; after that the tester has given up on the 0x78 and
    /// the step goes ahead regardless.
    #[inline(never)]
    fn diag_poll(&mut self) {
        if self.diag.quiescent() {
            return;
        }
        let now = now();
        if self.diag.resumes_after_send() && !can_io::all_sent(&TX_QUEUE) {
            let since = *self.resume_held_since.get_or_insert(now);
            let p2_us = u64::from(self.diag.server().config().p2_ms) * 1000;
            if now.micros_since(since) < p2_us {
                return;
            }
        }
        self.resume_held_since = None;
        self.diag.poll(now, &mut backend!(self));
    }

    /// Queues every frame the logic and the diagnostic stack have to send; returns the
    /// reset the tester asked for, if it did.
    #[inline(never)]
    fn transmit(&mut self) -> Option<ResetKind> {
        let tx_enabled = self.diag.server().normal_tx_enabled();
        while let Some(frame) = self.ecu.poll_transmit(now()) {
            self.diag.note_sent(now(), &frame);
            if tx_enabled {
                can_io::queue_for_transmit(&TX_QUEUE, frame);
                self.sent = self.sent.wrapping_add(1);
            }
        }
        while let Some(frame) = self.diag.poll_transmit(now()) {
            can_io::queue_for_transmit(&TX_QUEUE, frame);
            self.diag.confirm_transmit(now());
        }
        self.diag.take_reset()
    }
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
