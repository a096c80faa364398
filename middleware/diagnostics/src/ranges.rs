//! Every ECU: its frames well formed, its values inside their ranges.
//!
//! A sender clamps every value into its signal's range (spec section 3) and sends each
//! message at the catalogue's length, and CAN's CRC catches bits flipped on the wire, so
//! a frame with an out-of-range or undefined value, or of the wrong length, is the
//! sender's fault. Receivers drop such values and keep the last good one; the gateway
//! counts them per message (the car state) and this routine charges them to the message's
//! first sender. One is already a fault (faulty above [`FAULTY_FRAMES`]); there is no
//! suspect band.

use autoplug_can::{Node, MESSAGES};
use autoplug_gateway::{CarState, Update};
use autoplug_logs::LogFrame;

use crate::{Finding, Routine, Verdict};

/// The routine's name in findings.
pub const ROUTINE: &str = "values in range, frames of the right length";
/// Bad frames above which the ECU is faulty.
pub const FAULTY_FRAMES: f64 = 0.0;

/// The routine of one ECU.
pub struct Ranges {
    node: Node,
}

impl Ranges {
    /// The routine for `node`'s messages.
    pub fn new(node: Node) -> Self {
        Self { node }
    }
}

impl Routine for Ranges {
    fn ecu(&self) -> Node {
        self.node
    }

    // The car state already counts bad frames per message; nothing to do per frame.
    fn on_frame(&mut self, _frame: &LogFrame, _update: Update, _state: &CarState) {}

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let mut bad = 0u64;
        let mut worst: Option<(&str, u64, u64)> = None;
        for (spec, stats) in MESSAGES.iter().zip(state.stats()) {
            if spec.senders.first() != Some(&self.node) {
                continue;
            }
            let n = stats.invalid + stats.wrong_length;
            bad += n;
            if n > 0 && worst.is_none_or(|(_, w, _)| n > w) {
                worst = Some((spec.name, n, stats.wrong_length));
            }
        }
        let evidence = match worst {
            None => "every frame of the right length with every value in range".to_string(),
            Some((name, n, wrong_length)) => format!(
                "{bad} bad frame(s), most in {name}: {n} ({wrong_length} of the wrong length, the others with a value outside its range)"
            ),
        };
        vec![Finding {
            routine: ROUTINE,
            verdict: Verdict::of(bad as f64, FAULTY_FRAMES, FAULTY_FRAMES),
            value: Some(bad as f64),
            unit: "frames",
            suspect_above: FAULTY_FRAMES,
            faulty_above: FAULTY_FRAMES,
            window: None,
            evidence,
        }]
    }
}
