//! The pedals ECU's tasks: see the crate documentation in `main.rs`.

use autoplug_ecu::{EcuLogic, Instant};
use defmt_rtt as _;
use ecu_pedals::PedalsEcu;
use embassy_executor::Spawner;
use embassy_futures::select::{select, Either};
use embassy_stm32::can::{CanRx, CanTx};
use embassy_stm32::peripherals::IWDG;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Ticker};

use crate::board::{self, CommandOutputs, PedalInputs};
use crate::can_io::{self, RxQueue, TxQueue};

static RX_QUEUE: RxQueue = RxQueue::new();
static TX_QUEUE: TxQueue = TxQueue::new();

/// How often the control task logs the DTCs when they changed: every 100 steps (1 s).
const DTC_LOG_EVERY_STEPS: u32 = 100;

/// The logic's clock: microseconds since power-up.
fn now() -> Instant {
    Instant::from_micros(embassy_time::Instant::now().as_micros())
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let board::Board {
        mut can,
        pedals,
        commands,
        watchdog,
    } = board::init();
    defmt::info!("pedals ECU (node {}) starting", PedalsEcu::NODE);

    can_io::start(&mut can, PedalsEcu::NODE).await;
    let (tx, rx) = can.split();
    spawner.spawn(can_rx(rx).expect("can_rx spawned once"));
    spawner.spawn(can_tx(tx).expect("can_tx spawned once"));
    spawner.spawn(can_monitor().expect("can_monitor spawned once"));

    // The control loop runs here, in `main`, and never returns: `can` must stay alive, as
    // dropping the driver resets CAN1 under the RX and TX halves.
    control(pedals, commands, watchdog).await;
    #[allow(unreachable_code)]
    drop(can);
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

async fn control(
    mut pedals: PedalInputs,
    mut commands: CommandOutputs,
    mut watchdog: IndependentWatchdog<'static, IWDG>,
) -> ! {
    let mut ecu = PedalsEcu::new(now());
    let mut ticker = Ticker::every(Duration::from_micros(PedalsEcu::STEP_PERIOD_US));
    let mut steps: u32 = 0;
    let mut logged_dtcs = None;
    watchdog.unleash();
    loop {
        match select(ticker.next(), RX_QUEUE.receive()).await {
            Either::First(()) => {
                let sensors = pedals.read();
                let actuators = ecu.step(now(), &sensors);
                commands.set(&actuators);
                watchdog.pet();
                defmt::trace!(
                    "pedals: accel {} brake {} -> accel cmd {} brake cmd {}",
                    sensors.accelerator_pedal,
                    sensors.brake_pedal,
                    actuators.accelerator_cmd,
                    actuators.brake_cmd
                );
                steps = steps.wrapping_add(1);
                if steps % DTC_LOG_EVERY_STEPS == 0 {
                    log_dtcs_if_changed(&ecu, &mut logged_dtcs);
                }
            }
            Either::Second(frame) => ecu.on_frame(now(), &frame),
        }
        while let Some(frame) = ecu.poll_transmit(now()) {
            can_io::queue_for_transmit(&TX_QUEUE, frame);
        }
    }
}

/// Logs every DTC record when the set of records or their status changed since the last
/// log (`logged`: a summary of what was logged).
fn log_dtcs_if_changed(ecu: &PedalsEcu, logged: &mut Option<(usize, u32, u32)>) {
    let dtcs = ecu.dtcs();
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
