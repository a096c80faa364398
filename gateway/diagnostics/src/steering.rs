//! Steering: are the paddle requests the pulses the transmission expects?
//!
//! A paddle press becomes ShiftMsg Up or Down for `ecu_steering::SHIFT_PULSE_MS`, then
//! None again, and two requests are always separated by None (the transmission acts on
//! the None → Up/Down edge). Holding a paddle does not stretch the pulse. The routine
//! measures the longest Up or Down run on the bus and counts direct Up ↔ Down changes.
//! Thresholds: a pulse is 100 ms, seen within one 20 ms period of ShiftMsg either side;
//! over [`SUSPECT_S`] is a stretched pulse, over [`FAULTY_S`] a request stuck on (a
//! transmission would see one long request, or a second shift after its timeout). A
//! direct Up ↔ Down change is faulty on its own. (The steering angle's range is judged by
//! the range check every ECU gets; its rate is the driver's, not the ECU's.)

use autoplug_can::{Node, ShiftMsg, ShiftRequest, MESSAGES};
use autoplug_gateway::{CarState, Update};
use autoplug_logs::LogFrame;

use crate::span::LongestSpan;
use crate::{Finding, Routine, Verdict, Window};

/// Longest request above which the steering ECU is suspect, s.
pub const SUSPECT_S: f64 = 0.2;
/// Longest request above which the steering ECU is faulty, s.
pub const FAULTY_S: f64 = 0.5;

/// The steering routine.
#[derive(Default)]
pub struct Steering {
    request: LongestSpan,
    last: Option<ShiftRequest>,
    direct_changes: u64,
    first_direct: Option<u64>,
}

impl Routine for Steering {
    fn ecu(&self) -> Node {
        Node::Steering
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        if MESSAGES[index].id != ShiftMsg::ID {
            return;
        }
        let t = frame.t_us;
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
            "no paddle request seen".to_string()
        } else {
            format!("longest paddle request {:.3} s", value)
        };
        vec![Finding {
            routine: "paddle requests as pulses",
            verdict,
            value: (span.judged > 0).then_some(value),
            unit: "s",
            suspect_above: SUSPECT_S,
            faulty_above: FAULTY_S,
            window: span.longest.or(self.first_direct.map(|t| Window {
                from_us: t,
                to_us: t,
            })),
            evidence,
        }]
    }
}
