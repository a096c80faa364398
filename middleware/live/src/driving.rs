//! A person driving the virtual car from the dashboard: the desk between the session (which
//! takes the browser's inputs) and the car's source (which applies them before each tick).
//!
//! The inputs are the car's sensor inputs (pedals, wheel, switches, knob, buttons), not CAN
//! frames: they enter the simulation, and the gateway sees only what the ECUs then put on
//! the bus. Both ends live on the session's thread.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::driver::HeldControls;
use autoplug_virtual_car::scenario::Button;

/// Inputs waiting for the car at most (the car takes them every millisecond of simulated
/// time; a browser sends a few dozen per second).
const MAX_WAITING: usize = 256;

/// With no input from the page that drives for this long, the pedals are released: a
/// closed laptop or a lost network must not leave the virtual foot down, on either pedal.
/// (Wall time: this is about the person, not the simulation.)
pub const DEAD_MAN: Duration = Duration::from_secs(1);

/// One input of the person at the wheel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DeskInput {
    /// The controls as held now.
    Hold(HeldControls),
    /// A steering-wheel button.
    Press(Button),
    /// The page went away: pedals released.
    Release,
    /// The road's friction, left and right (already checked against its range).
    Friction(f64, f64),
    /// Back to the start line (refused by the car while it moves).
    ToStart,
    /// The simulator steers along the road (`true`) or the person steers.
    SteerAlongRoad(bool),
}

/// What the car's side reports back for the dashboard.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeskReport {
    /// The controls as the person holds them, once someone took the wheel.
    pub held: Option<HeldControls>,
    /// The road's friction, left and right.
    pub friction: (f64, f64),
    /// The car's speed (the simulator's), m/s.
    pub speed_mps: f64,
    /// The car has a track (a road to steer along).
    pub on_track: bool,
    /// The simulator steers along the road.
    pub steers_along_road: bool,
}

/// The desk (see the module docs).
#[derive(Debug, Default)]
pub struct DriverDesk {
    waiting: VecDeque<DeskInput>,
    last_input: Option<Instant>,
    released: bool,
    report: DeskReport,
}

impl DriverDesk {
    /// An empty desk.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes an input from the page. When the queue is full, a newer `Hold` replaces the
    /// oldest waiting one (only the latest position of a pedal matters); other inputs
    /// are refused.
    pub fn push(&mut self, input: DeskInput) -> Result<(), &'static str> {
        if matches!(input, DeskInput::Hold(_) | DeskInput::Press(_)) {
            self.last_input = Some(Instant::now());
            self.released = false;
        }
        if self.waiting.len() >= MAX_WAITING {
            let Some(old) = self
                .waiting
                .iter()
                .position(|i| matches!(i, DeskInput::Hold(_)))
            else {
                return Err("too many inputs waiting");
            };
            self.waiting.remove(old);
        }
        self.waiting.push_back(input);
        Ok(())
    }

    /// The car's side: applies what waits, and the dead man's release.
    pub fn apply(&mut self, car: &mut VirtualCar) {
        while let Some(input) = self.waiting.pop_front() {
            match input {
                DeskInput::Hold(held) => {
                    // Clamped by the driver; a NaN was refused by the session already.
                    let _ = car.take_wheel().hold(held);
                }
                DeskInput::Press(button) => car.take_wheel().press(button),
                DeskInput::Release => self.release(car),
                DeskInput::Friction(left, right) => {
                    let _ = car.set_friction(left, right);
                }
                DeskInput::ToStart => {
                    // The session checked the car stands; one that moved off since stays.
                    let _ = car.back_to_start();
                }
                DeskInput::SteerAlongRoad(on) => {
                    // The session checked the car has a track.
                    let _ = car.set_steering_along_road(on);
                }
            }
        }
        if !self.released
            && self.last_input.is_some_and(|t| t.elapsed() >= DEAD_MAN)
            && car.manual_driver().is_some()
        {
            self.release(car);
        }
        self.report = DeskReport {
            held: car.manual_driver().map(|d| *d.held()),
            friction: car.friction(),
            speed_mps: car.vehicle().speed_mps,
            on_track: car.track().is_some(),
            steers_along_road: car.steers_along_road(),
        };
    }

    fn release(&mut self, car: &mut VirtualCar) {
        self.released = true;
        if let Some(driver) = car.manual_driver() {
            // Both pedals: a brake left on is as stuck as an accelerator (the brake lights
            // on, the car held) when nobody holds it any more.
            let held = HeldControls {
                accelerator: 0.0,
                brake: 0.0,
                ..*driver.held()
            };
            let _ = car.take_wheel().hold(held);
        }
    }

    /// What the car's side last reported.
    pub fn report(&self) -> DeskReport {
        self.report
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_virtual_car::scenario::Scenario;

    #[test]
    fn a_release_lets_go_of_both_pedals() {
        let scenario = Scenario::parse("name = \"desk\"\nduration_s = 60.0\n", "test").unwrap();
        let mut car = VirtualCar::new(&scenario);
        let mut desk = DriverDesk::new();
        let held = HeldControls {
            accelerator: 30.0,
            brake: 80.0,
            steering_deg: 12.0,
            headlights: true,
            economy_mode: false,
            manual_mode: false,
            set_temp_f: 70.0,
        };
        desk.push(DeskInput::Hold(held)).unwrap();
        desk.apply(&mut car);
        assert_eq!(car.manual_driver().unwrap().held().brake, 80.0);
        desk.push(DeskInput::Release).unwrap();
        desk.apply(&mut car);
        let after = *car.manual_driver().unwrap().held();
        assert_eq!((after.accelerator, after.brake), (0.0, 0.0));
        // What the person set stays: the wheel, the switches.
        assert_eq!(after.steering_deg, 12.0);
        assert!(after.headlights);
    }
}
