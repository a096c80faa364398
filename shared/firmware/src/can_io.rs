//! CAN1 glue between the bxCAN driver and the logic's [`autoplug_can::Frame`]s: the
//! interrupt binding, bit rate, acceptance filters from the catalogue, the RX and TX tasks,
//! and the error monitor. The pins are the board's: each board module passes its own to
//! `Can::new` together with [`Irqs`].

use core::num::{NonZeroU16, NonZeroU8};
use core::sync::atomic::{AtomicU32, Ordering};

use autoplug_can::{Frame, Node};
use embassy_stm32::bind_interrupts;
use embassy_stm32::can::filter::ListEntry16;
use embassy_stm32::can::{self as bxcan, Can, CanRx, CanTx, Fifo, Id, StandardId};
use embassy_stm32::pac;
use embassy_stm32::peripherals::CAN1;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Ticker};

bind_interrupts!(
    /// CAN1's four interrupts bound to the bxCAN driver: pass to `Can::new`.
    pub struct Irqs {
        CAN1_TX => bxcan::TxInterruptHandler<CAN1>;
        CAN1_RX0 => bxcan::Rx0InterruptHandler<CAN1>;
        CAN1_RX1 => bxcan::Rx1InterruptHandler<CAN1>;
        CAN1_SCE => bxcan::SceInterruptHandler<CAN1>;
    }
);

/// Identifiers the acceptance filters take: 4 per bank of CAN1's 14.
const MAX_FILTER_IDS: usize = 4 * 14;

/// The AutoPlug bus bit rate.
pub const BITRATE: u32 = 500_000;

/// CAN1's bit timing for [`BITRATE`] from APB1: a prescaler of 6 makes 7 MHz time quanta,
/// 14 per bit (sync 1 + segment 1 of 11 + segment 2 of 2), sampled at 12/14 = 85.7 %, with
/// a resynchronisation jump width of 1. That is what the HAL's `set_bitrate` would work out
/// at every start; given here as constants (checked below) so the firmware carries neither
/// the search nor its error's formatting.
const BIT_TIMING: bxcan::util::NominalBitTiming = bxcan::util::NominalBitTiming {
    prescaler: NonZeroU16::new(6).unwrap(),
    seg1: NonZeroU8::new(11).unwrap(),
    seg2: NonZeroU8::new(2).unwrap(),
    sync_jump_width: NonZeroU8::new(1).unwrap(),
};
const _: () = {
    let quanta = 1 + BIT_TIMING.seg1.get() as u32 + BIT_TIMING.seg2.get() as u32;
    let cycles = BIT_TIMING.prescaler.get() as u32 * quanta;
    assert!(crate::clocks::APB1_HZ % cycles == 0 && crate::clocks::APB1_HZ / cycles == BITRATE);
    // bxCAN's limits: segment 1 at most 16 quanta, segment 2 at most 8.
    assert!(BIT_TIMING.seg1.get() <= 16 && BIT_TIMING.seg2.get() <= 8);
};

/// Frames received, waiting for the control task (a 10 ms step sees at most a few).
pub type RxQueue = Channel<CriticalSectionRawMutex, Frame, 16>;

/// Frames the logic asked to send, waiting for a transmit mailbox.
pub type TxQueue = Channel<CriticalSectionRawMutex, Frame, 8>;

/// Frames dropped because the RX queue was full (the control task fell behind).
pub static RX_DROPPED: AtomicU32 = AtomicU32::new(0);
/// Frames dropped because the TX queue was full (the bus is off or saturated).
pub static TX_DROPPED: AtomicU32 = AtomicU32::new(0);
/// Bus errors (last error code) reported by the driver.
pub static BUS_ERRORS: AtomicU32 = AtomicU32::new(0);

/// Configures CAN1 for the AutoPlug bus: 500 kbit/s, automatic retransmission, and
/// acceptance filters for exactly the data frames `node` receives, its diagnostic ones
/// included (list mode, four 11-bit identifiers per bank). Then
/// joins the bus. Bus-off recovery is the hardware's: the driver sets ABOM, so after bus-off
/// the controller rejoins on its own once it has seen 128 × 11 recessive bits.
pub async fn start(can: &mut Can<'static>, node: Node) {
    can.modify_config()
        .set_bit_timing(BIT_TIMING)
        .set_loopback(false)
        .set_silent(false)
        .set_automatic_retransmit(true);

    // The application's inputs, then the diagnostic ones: the node's UDS requests, the
    // functional identifier, and the vehicle speed (no programming while the car moves).
    let mut buffer = [0u16; MAX_FILTER_IDS];
    let mut len = 0;
    let diagnostic = [
        node.diag_request_id(),
        Some(autoplug_can::DIAG_FUNCTIONAL_REQUEST_ID),
        Some(autoplug_can::VehicleSpeedMsg::ID),
    ];
    for id in node
        .received_ids()
        .iter()
        .copied()
        .chain(diagnostic.into_iter().flatten())
    {
        if !buffer[..len].contains(&id) && len < MAX_FILTER_IDS {
            buffer[len] = id;
            len += 1;
        }
    }
    let ids = &buffer[..len];
    let mut filters = can.modify_filters();
    filters.clear();
    for (bank, chunk) in ids.chunks(4).enumerate() {
        // A bank holds exactly four entries: repeat the last identifier to fill it.
        let entry = |i: usize| {
            let id = chunk[i.min(chunk.len() - 1)];
            // Catalogue identifiers are 11-bit (checked by autoplug-can's build script).
            ListEntry16::data_frames_with_id(StandardId::new(id).unwrap_or(StandardId::ZERO))
        };
        filters.enable_bank(
            bank as u8,
            Fifo::Fifo0,
            [entry(0), entry(1), entry(2), entry(3)],
        );
    }
    drop(filters);
    defmt::info!(
        "CAN1: {} bit/s, accepting {=[?]} ({} filter banks)",
        BITRATE,
        ids,
        ids.len().div_ceil(4)
    );

    can.enable().await;
    defmt::info!("CAN1: on the bus");
}

/// Receives frames and queues them for the control task.
pub async fn receive(mut rx: CanRx<'static>, queue: &'static RxQueue) -> ! {
    loop {
        match rx.read().await {
            Ok(envelope) => {
                if let Some(frame) = from_bxcan(&envelope.frame) {
                    if queue.try_send(frame).is_err() {
                        RX_DROPPED.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            Err(error) => {
                BUS_ERRORS.fetch_add(1, Ordering::Relaxed);
                defmt::debug!("CAN1: bus error {}", error);
            }
        }
    }
}

/// Sends the frames the control task queued, in order, waiting for a free mailbox.
pub async fn transmit(mut tx: CanTx<'static>, queue: &'static TxQueue) -> ! {
    loop {
        let frame = queue.receive().await;
        let Some(mut frame) = to_bxcan(&frame) else {
            continue;
        };
        // With all three mailboxes full, the driver may swap out a pending frame of lower
        // priority to queue this one: send that one next rather than lose it.
        while let Some(dequeued) = tx.write(&frame).await.dequeued_frame() {
            frame = *dequeued;
        }
    }
}

/// Whether every frame queued for [`transmit`] is on the bus: the queue empty and CAN1's
/// three transmit mailboxes empty (the transmit task holds a frame only while it waits
/// for a mailbox, when none is empty).
pub fn all_sent(queue: &TxQueue) -> bool {
    let tsr = pac::CAN1.tsr().read();
    queue.is_empty() && tsr.tme(0) && tsr.tme(1) && tsr.tme(2)
}

/// Queues a frame for [`transmit`] without waiting; counts it as dropped if the queue is
/// full (the bus is off or saturated), so the control loop never blocks on the bus.
pub fn queue_for_transmit(queue: &TxQueue, frame: Frame) {
    if queue.try_send(frame).is_err() {
        TX_DROPPED.fetch_add(1, Ordering::Relaxed);
    }
}

/// Logs CAN1's error state once a second when it changed: transmit and receive error
/// counters, error-warning / error-passive / bus-off flags, last error code, and the
/// firmware's drop and bus-error counts. Bus-off and its recovery are logged as warnings.
pub async fn monitor() -> ! {
    let mut ticker = Ticker::every(Duration::from_secs(1));
    let mut last = None;
    let mut was_bus_off = false;
    loop {
        ticker.next().await;
        let esr = pac::CAN1.esr().read();
        let bus_off = esr.boff();
        if bus_off != was_bus_off {
            if bus_off {
                defmt::warn!("CAN1: bus-off (TEC > 255), automatic recovery under way");
            } else {
                defmt::warn!("CAN1: recovered from bus-off");
            }
            was_bus_off = bus_off;
        }
        let state = (
            esr.tec(),
            esr.rec(),
            esr.ewgf(),
            esr.epvf(),
            esr.lec().to_bits(),
            RX_DROPPED.load(Ordering::Relaxed),
            TX_DROPPED.load(Ordering::Relaxed),
            BUS_ERRORS.load(Ordering::Relaxed),
        );
        if last != Some(state) {
            let (tec, rec, warning, passive, lec, rx_dropped, tx_dropped, bus_errors) = state;
            defmt::info!(
                "CAN1: TEC {} REC {} warning {} passive {} bus-off {} LEC {}, dropped rx {} tx {}, bus errors {}",
                tec,
                rec,
                warning,
                passive,
                bus_off,
                lec,
                rx_dropped,
                tx_dropped,
                bus_errors
            );
            last = Some(state);
        }
    }
}

/// A received data frame as the logic sees it; `None` for an extended identifier (the
/// filters let none through).
fn from_bxcan(frame: &bxcan::Frame) -> Option<Frame> {
    match frame.id() {
        Id::Standard(id) => Frame::new(u32::from(id.as_raw()), frame.data()).ok(),
        Id::Extended(_) => None,
    }
}

/// A frame of the logic as the driver sends it.
fn to_bxcan(frame: &Frame) -> Option<bxcan::Frame> {
    match bxcan::Frame::new_standard(frame.id(), frame.data()) {
        Ok(frame) => Some(frame),
        Err(error) => {
            defmt::error!("CAN1: cannot send {}: {}", frame, error);
            None
        }
    }
}
