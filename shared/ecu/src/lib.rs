//! What every AutoPlug ECU's logic shares.
//!
//! Each ECU's behaviour is a `no_std` state machine (an [`EcuLogic`]): received frames,
//! sensor readings and time go in; actuator commands and frames to send come out. The
//! firmware wires it to Embassy peripherals, the virtual car to the vehicle model: both
//! run this same code. The pieces here are the ones all nine need:
//!
//! - [`Instant`]: time passed in by the caller, never read from a clock;
//! - [`PeriodicTx`]: the catalogue's transmit timing (period, on change, minimum gap);
//! - [`Input`]: a consumed message with its last good value and staleness (3 periods);
//! - [`DtcStore`]: the ECU's diagnostic trouble codes with ISO 14229-1 status bits;
//! - [`supervise`] and [`receive`]: the input bookkeeping every ECU does the same way.
#![no_std]
#![deny(missing_docs)]

mod dtc;
mod input;
pub mod pins;
mod time;
mod tx;

pub use dtc::{
    invalid_data, lost_communication, status, Dtc, DtcRecord, DtcStore, DtcSystem,
    FTB_MISSING_MESSAGE, FTB_SIGNAL_INVALID, FTB_SIGNAL_PLAUSIBILITY,
};
pub use input::{Freshness, Input, STALE_AFTER_PERIODS};
pub use time::Instant;
pub use tx::PeriodicTx;

use autoplug_can::{CanMessage, Frame, Node};

/// Which software an ECU with a demonstration fault runs (report section 5.4: the broken
/// cruise control and the broken ABS). Each such crate documents what its `Faulty` does
/// and selects its build's variant with its own `faulty` cargo feature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Variant {
    /// The working software.
    Correct,
    /// The demonstration's broken software.
    Faulty,
}

/// How many different DTCs an ECU stores.
pub const DTC_CAPACITY: usize = 16;

/// The DTC store every ECU has.
pub type Dtcs = DtcStore<DTC_CAPACITY>;

/// One ECU's behaviour, as the firmware and the virtual car drive it.
pub trait EcuLogic {
    /// Readings from the ECU's own sensors and switches.
    type Sensors;
    /// Commands to the ECU's own actuators.
    type Actuators;

    /// The node this logic runs on.
    const NODE: Node;
    /// How often [`EcuLogic::step`] runs, in microseconds.
    const STEP_PERIOD_US: u64;

    /// A frame the ECU's acceptance filter let through. Frames of other identifiers are
    /// ignored.
    fn on_frame(&mut self, now: Instant, frame: &Frame);

    /// One control step: reads sensors and the inputs received so far, updates the
    /// outputs and the frames to send.
    fn step(&mut self, now: Instant, sensors: &Self::Sensors) -> Self::Actuators;

    /// Whether a frame received since the last step carries a command that must take
    /// effect now rather than up to one period later (the brake pedal pressed: at
    /// 100 km/h each millisecond of waiting adds 28 mm to the stop). The runtime then runs
    /// a step at once and counts the next period from it. Such a step may follow the last
    /// one closely, so a logic that asks bounds how often (the ABS: once per 100 ms).
    /// `false` unless the logic says otherwise.
    fn step_requested(&self) -> bool {
        false
    }

    /// The next frame to send now, if any is due; call until `None`.
    fn poll_transmit(&mut self, now: Instant) -> Option<Frame>;

    /// The DTCs recorded so far.
    fn dtcs(&self) -> &Dtcs;

    /// The DTCs, for the diagnostic server: cleared by 0x14, paused by 0x85.
    fn dtcs_mut(&mut self) -> &mut Dtcs;

    /// Whether the ECU's own sensors, at the last step, show the car moving or the engine
    /// above idle: a veto on reprogramming whatever the bus says (a spoofed standstill on
    /// the bus does not stop the ABS's wheels turning). `false` for an ECU without such
    /// sensors.
    fn own_sensors_show_motion(&self) -> bool {
        false
    }
}

/// Offers a frame to an input. A refused frame records "invalid data" against the
/// message's sender. Returns whether the frame was this input's message.
pub fn receive<M: CanMessage>(
    input: &mut Input<M>,
    dtcs: &mut Dtcs,
    now: Instant,
    frame: &Frame,
) -> bool {
    receive_from(sender_of::<M>(), input, dtcs, now, frame)
}

/// [`receive`] for a message with several senders, charging faults to `sender`, the one
/// this ECU listens to (CruiseModeMsg: the steering ECU hears only the pedals' cancels).
pub fn receive_from<M: CanMessage>(
    sender: Node,
    input: &mut Input<M>,
    dtcs: &mut Dtcs,
    now: Instant,
    frame: &Frame,
) -> bool {
    let dtc = invalid_data(sender);
    match input.accept(now, frame) {
        None => false,
        Some(Ok(())) => {
            dtcs.report_passed(dtc);
            true
        }
        Some(Err(error)) => {
            if dtcs.report_failed(dtc, now) {
                autoplug_log::warn!("{}: invalid frame ({:?}), DTC recorded", M::NAME, error);
            }
            true
        }
    }
}

/// Re-checks an input's freshness, records or clears "lost communication" with its
/// sender, and returns whether it is stale (the caller then applies its safe state).
pub fn supervise<M: CanMessage>(input: &mut Input<M>, dtcs: &mut Dtcs, now: Instant) -> bool {
    let dtc = lost_communication(sender_of::<M>());
    match input.check(now) {
        Some(Freshness::Stale) => {
            dtcs.report_failed(dtc, now);
            autoplug_log::warn!("{}: stale, safe state", M::NAME);
        }
        Some(Freshness::Fresh) => {
            dtcs.report_passed(dtc);
            autoplug_log::info!("{}: fresh again", M::NAME);
        }
        None => {}
    }
    input.is_stale()
}

/// The node a message's faults are charged to: its first sender in the catalogue.
fn sender_of<M: CanMessage>() -> Node {
    M::SENDERS.first().copied().unwrap_or(Node::Gateway)
}

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

/// Lists an ECU's shared test cases (functions of its `test_cases` module) once, for both
/// runners: `CASES`, name and function, for the on-target suite that runs every ECU's cases
/// from a table; and a host `#[test]` per case (module `each_case`).
///
/// Written where the cases are (`test_cases!(a_case, another_case);` at the end of the
/// module), so a case added there is run on the host and on the target alike.
#[macro_export]
macro_rules! test_cases {
    ($($case:ident),* $(,)?) => {
        /// Every case of this module by name, in the order listed.
        pub const CASES: &[(&str, fn())] = &[$((stringify!($case), $case)),*];

        #[cfg(test)]
        mod each_case {
            $(
                #[test]
                fn $case() {
                    super::$case();
                }
            )*
        }
    };
}

#[cfg(test)]
mod tests;
