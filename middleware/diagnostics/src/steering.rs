//! Steering: are the paddle requests the pulses the transmission expects, and does the wheel
//! turn no faster than a hand can turn it?
//!
//! **Paddle requests as pulses.** A paddle press becomes ShiftMsg Up or Down for `autoplug_ecu_params::steering::SHIFT_PULSE_MS`, then
//! None again, and two requests are always separated by None (the transmission acts on
//! the None → Up/Down edge). Holding a paddle does not stretch the pulse. The routine
//! measures the longest Up or Down run on the bus and counts direct Up ↔ Down changes.
//! Thresholds: a pulse is 100 ms, seen within one 20 ms period of ShiftMsg either side;
//! over [`SUSPECT_S`] is a stretched pulse, over [`FAULTY_S`] a request stuck on (a
//! transmission would see one long request, or a second shift after its timeout). A
//! direct Up ↔ Down change is faulty on its own.
//!
//! **Steering angle rate.** How fast the wheel turns is the driver's choice, but only up
//! to what a hand can do: the routine measures the largest rate of the angle over
//! [`RATE_WINDOW_US`] (over a shorter time the 3.375° steps of SteeringMsg would pass for
//! speed). Fast drivers' corrections reach about 1000 °/s; a sensor that jumps, a broken
//! track or a loose wiper does far more: suspect above [`RATE_SUSPECT_DEG_S`], faulty above
//! [`RATE_FAULTY_DEG_S`]. The shipped scenarios peak at 225 °/s (the step steer). The
//! angle's range is judged by the range check every ECU gets.

use std::collections::VecDeque;

use autoplug_can::{Node, ShiftMsg, ShiftRequest, SteeringMsg, MESSAGES};
use autoplug_gateway::{CarState, Update};
use autoplug_logs::LogFrame;

use crate::span::LongestSpan;
use crate::{Finding, Routine, Verdict, Window};

/// Longest request above which the steering ECU is suspect, s.
pub const SUSPECT_S: f64 = 0.2;
/// Longest request above which the steering ECU is faulty, s.
pub const FAULTY_S: f64 = 0.5;

/// Angle rates are measured over at least this long, µs.
pub const RATE_WINDOW_US: u64 = 50_000;
/// Angle rate above which the steering ECU is suspect, °/s.
pub const RATE_SUSPECT_DEG_S: f64 = 1500.0;
/// Angle rate above which the steering ECU is faulty, °/s.
pub const RATE_FAULTY_DEG_S: f64 = 3000.0;

/// The steering routine.
#[derive(Default)]
pub struct Steering {
    request: LongestSpan,
    last: Option<ShiftRequest>,
    direct_changes: u64,
    first_direct: Option<u64>,
    /// Angles of the last [`RATE_WINDOW_US`] (and the one before), µs and degrees.
    angles: VecDeque<(u64, f64)>,
    fastest: Option<(f64, Window)>,
}

impl Steering {
    fn on_angle(&mut self, t: u64, angle: f64) {
        if self.angles.back().is_some_and(|(last, _)| {
            t < *last || t - *last > 3 * u64::from(SteeringMsg::CYCLE_TIME_MS) * 1000
        }) {
            // Out of order, or after a silence: no rate across it.
            self.angles.clear();
        }
        self.angles.push_back((t, angle));
        while self
            .angles
            .get(1)
            .is_some_and(|(t1, _)| t - t1 >= RATE_WINDOW_US)
        {
            self.angles.pop_front();
        }
        if let Some(&(t0, a0)) = self.angles.front() {
            let dt = t - t0;
            if dt >= RATE_WINDOW_US {
                let rate = (angle - a0).abs() / (dt as f64 * 1e-6);
                if self.fastest.is_none_or(|(r, _)| rate > r) {
                    self.fastest = Some((
                        rate,
                        Window {
                            from_us: t0,
                            to_us: t,
                        },
                    ));
                }
            }
        }
    }
}

impl Routine for Steering {
    fn ecu(&self) -> Node {
        Node::Steering
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let t = frame.t_us;
        if MESSAGES[index].id == SteeringMsg::ID {
            let angle = f64::from(state.get::<SteeringMsg>().steering_angle);
            self.on_angle(t, angle);
            return;
        }
        if MESSAGES[index].id != ShiftMsg::ID {
            return;
        }
        let request = state.get::<ShiftMsg>().shift_request;
        // A change of request starts a new run.
        if self.last.is_some_and(|l| l != request) {
            self.request.end(t);
        }
        if matches!(
            (self.last, request),
            (Some(ShiftRequest::Up), ShiftRequest::Down)
                | (Some(ShiftRequest::Down), ShiftRequest::Up)
        ) {
            self.direct_changes += 1;
            self.first_direct.get_or_insert(t);
        }
        self.last = Some(request);
        self.request.observe(t, true, request != ShiftRequest::None);
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let span = self.request.until(state.now_us());
        let value = span.seconds();
        let mut verdict = Verdict::of(value, SUSPECT_S, FAULTY_S);
        let evidence = if self.direct_changes > 0 {
            verdict = Verdict::Faulty;
            format!(
                "{} direct change(s) between Up and Down without None, the first at {:.2} s",
                self.direct_changes,
                self.first_direct.unwrap_or(0) as f64 * 1e-6
            )
        } else if span.longest.is_none() {
            // No request to judge: nothing shows the paddles work.
            verdict = Verdict::NotExercised;
            "not exercised: no paddle request seen".to_string()
        } else {
            format!("longest paddle request {:.3} s", value)
        };
        vec![
            Finding {
                routine: "paddle requests as pulses",
                verdict,
                value: (verdict != Verdict::NotExercised).then_some(value),
                unit: "s",
                suspect_above: SUSPECT_S,
                faulty_above: FAULTY_S,
                window: span.longest.or(self.first_direct.map(|t| Window {
                    from_us: t,
                    to_us: t,
                })),
                evidence,
            },
            self.rate_finding(),
        ]
    }
}

impl Steering {
    fn rate_finding(&self) -> Finding {
        let rate = self.fastest.map(|(r, _)| r);
        Finding {
            routine: "steering angle rate",
            verdict: rate.map_or(Verdict::NotExercised, |rate| {
                Verdict::of(rate, RATE_SUSPECT_DEG_S, RATE_FAULTY_DEG_S)
            }),
            value: rate,
            unit: "deg/s",
            suspect_above: RATE_SUSPECT_DEG_S,
            faulty_above: RATE_FAULTY_DEG_S,
            window: self.fastest.map(|(_, w)| w),
            evidence: match self.fastest {
                Some((r, w)) => format!(
                    "fastest turn of the wheel {r:.0} deg/s from {:.2} s",
                    w.from_us as f64 * 1e-6
                ),
                None => "not exercised: SteeringMsg never arrived for 50 ms in a row".into(),
            },
        }
    }
}
