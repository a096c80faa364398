//! The in-process virtual car as a tester's bus: a [`Job`] runs on the car's simulated time,
//! its frames go through the car's external node onto the bit-timed bus (so a download
//! takes there what it takes on 500 kbit/s CAN), and the car goes on with its scenario
//! meanwhile. Nothing here reads a wall clock: a run replays exactly.

use autoplug_can::Frame;
use autoplug_ecu::Instant;
use autoplug_virtual_car::car::VirtualCar;

use autoplug_tester::Job;

/// A job attached to a car's external node.
pub struct OnCar<J: Job> {
    job: J,
    /// A frame the external node's transmit queue could not take yet.
    held: Option<Frame>,
    finished: bool,
}

impl<J: Job> OnCar<J> {
    /// Attaches `job` to `car` (the car starts handing over what its external node hears).
    pub fn new(job: J, car: &mut VirtualCar) -> Self {
        car.capture_external_rx(true);
        Self {
            job,
            held: None,
            finished: false,
        }
    }

    /// One step, after each tick of the car: the frames received go to the job, the job's
    /// frames go on the bus. Returns the job's result once, when it has one.
    pub fn step(&mut self, car: &mut VirtualCar) -> Option<Result<J::Output, J::Error>> {
        if self.finished {
            return None;
        }
        let now = Instant::from_micros(car.time_us());
        for frame in car.take_external_rx() {
            self.job.on_frame(now, &frame);
        }
        self.job.poll(now);
        loop {
            let frame = match self.held.take() {
                Some(frame) => frame,
                None => match self.job.poll_transmit(now) {
                    Some(frame) => frame,
                    None => break,
                },
            };
            // The job is told a frame is out once the node has queued it; STmin is 0 on
            // this network, so the bus paces the frames.
            if car.inject(frame) {
                self.job.confirm_transmit(now);
            } else {
                self.held = Some(frame);
                break;
            }
        }
        let result = self.job.take_result();
        if result.is_some() {
            self.finished = true;
            car.capture_external_rx(false);
        }
        result
    }

    /// Runs the car until the job ends (or `limit_us` of simulated time passes: `None`).
    pub fn run(
        &mut self,
        car: &mut VirtualCar,
        limit_us: u64,
    ) -> Option<Result<J::Output, J::Error>> {
        let end = car.time_us() + limit_us;
        while car.time_us() < end {
            car.tick();
            if let Some(result) = self.step(car) {
                return Some(result);
            }
        }
        None
    }

    /// The job.
    pub fn job(&self) -> &J {
        &self.job
    }
}
