//! Live frame sources for the gateway: the virtual car in this process. (socketcand and
//! SocketCAN follow, over the transports of [`crate::transport`].)

use std::collections::VecDeque;
use std::time::Duration;

use autoplug_gateway::{FrameSource, Poll, SourceError};
use autoplug_logs::LogFrame;
use autoplug_virtual_car::car::VirtualCar;

/// The virtual car's bus as a live source: each poll runs the car on until it has put
/// frames on the bus, and hands them over in bus order with their bus time. The gateway
/// sees exactly what the car's bus log holds, and nothing of its internals.
pub struct VirtualCarSource {
    car: VirtualCar,
    pending: VecDeque<LogFrame>,
}

impl VirtualCarSource {
    /// The source for a car (normally just built from a scenario).
    pub fn new(car: VirtualCar) -> Self {
        Self {
            car,
            pending: VecDeque::new(),
        }
    }

    /// The car, for its own reports after the run.
    pub fn car(&self) -> &VirtualCar {
        &self.car
    }
}

impl FrameSource for VirtualCarSource {
    fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Poll::Frame(frame));
            }
            if self.car.finished() {
                return Ok(Poll::End);
            }
            self.car.tick();
            // Taken, not copied: a long live run keeps no frames in the car.
            self.pending.extend(
                self.car
                    .take_log()
                    .iter()
                    .map(|f| LogFrame::from_can(f.t_us, 0, &f.frame)),
            );
        }
    }

    fn describe(&self) -> String {
        format!("virtual car ({})", self.car.scenario().name)
    }
}
