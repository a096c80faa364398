//! The write side of the dashboard: what a browser (with the token) asks of the session
//! that runs the gateway, and how it gets there.
//!
//! The server never touches the bus, the car or the files itself: it checks the token and
//! the request's form, and hands a [`Command`] to the session's thread through a bounded
//! queue ([`CONTROL_QUEUE`] commands). The session takes them between two frames, acts,
//! and answers each [`Action`] (accepted, with a JSON body, or refused, with the reason);
//! what follows (a flash's progress, the recording's size) appears in the stream's
//! `session` object. A full queue is answered 503 at once: a flood of requests never
//! blocks the server or the car.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError};

use serde::Deserialize;
use tokio::sync::oneshot;

/// Commands waiting for the session at most.
pub const CONTROL_QUEUE: usize = 256;

/// Something that changes the car or the session, answered once.
#[derive(Debug)]
pub enum Action {
    /// Flash a signed image to one ECU (by its command-line name, e.g. `cruise`).
    Flash {
        /// The ECU.
        ecu: String,
        /// The image, as a file holds it.
        image: Vec<u8>,
        /// Where it came from (a library name or "upload"), for the report.
        origin: String,
    },
    /// Clear the trouble codes of one ECU, or of all nine (`None`).
    ClearDtcs {
        /// The ECU, or all.
        ecu: Option<String>,
    },
    /// Start the gateway's routines for one ECU, or for all nine (`None`), over: a verdict
    /// that no longer holds (the fault fixed, or judged in a moment that proves nothing).
    ResetVerdict {
        /// The ECU, or all.
        ecu: Option<String>,
    },
    /// Start (`true`) or stop the recording of all traffic.
    Record(bool),
    /// Change the road's friction (virtual car only), left and right wheels.
    Road {
        /// Left wheels.
        mu_left: f64,
        /// Right wheels.
        mu_right: f64,
    },
    /// Take the standing virtual car back to its start line.
    RoadStart,
    /// The simulator steers the virtual car along its road (`true`), or the person does.
    RoadSteering(bool),
    /// Control a replay.
    Replay(ReplayAction),
    /// Open a recording in a replay dashboard of its own (a second page, beside the live
    /// one).
    ReplayRecording {
        /// The recording (already checked to be a file in the recordings directory).
        path: std::path::PathBuf,
    },
    /// The driver's answer to the fleet's offer of an update.
    CampaignConsent {
        /// The campaign offered.
        campaign: i64,
        /// Install it (when parked), or not.
        install: bool,
    },
}

/// What a replay does next: `{"action":"play"}`, `"pause"`, `{"action":"speed","speed":X}`,
/// `{"action":"seek","t":S}`.
///
/// Parsed through a plain struct rather than serde's internally tagged enums: those
/// buffer numbers through `deserialize_any`, which breaks when a crate in the same build
/// turns on serde_json's `arbitrary_precision` (defmt-decoder does).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReplayAction {
    /// Go on at the set speed.
    Play,
    /// Stop the clock.
    Pause,
    /// Play at this multiple of the log's own time.
    Speed {
        /// The multiple (0.1..=100).
        speed: f64,
    },
    /// Jump to this time from the log's start, s.
    Seek {
        /// Seconds from the start.
        t: f64,
    },
}

impl<'de> Deserialize<'de> for ReplayAction {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Raw {
            action: String,
            speed: Option<f64>,
            t: Option<f64>,
        }
        let raw = Raw::deserialize(deserializer)?;
        let extra = |field: &'static str| D::Error::unknown_field(field, &[]);
        match raw.action.as_str() {
            "play" | "pause" => {
                if raw.speed.is_some() {
                    return Err(extra("speed"));
                }
                if raw.t.is_some() {
                    return Err(extra("t"));
                }
                Ok(if raw.action == "play" {
                    ReplayAction::Play
                } else {
                    ReplayAction::Pause
                })
            }
            "speed" => {
                if raw.t.is_some() {
                    return Err(D::Error::unknown_field("t", &["speed"]));
                }
                let speed = raw.speed.ok_or_else(|| D::Error::missing_field("speed"))?;
                Ok(ReplayAction::Speed { speed })
            }
            "seek" => {
                if raw.speed.is_some() {
                    return Err(D::Error::unknown_field("speed", &["t"]));
                }
                let t = raw.t.ok_or_else(|| D::Error::missing_field("t"))?;
                Ok(ReplayAction::Seek { t })
            }
            other => Err(D::Error::unknown_variant(
                other,
                &["play", "pause", "speed", "seek"],
            )),
        }
    }
}

/// What a person at the wheel holds (the Drive view sends it while it drives) and the
/// steering-wheel buttons: the virtual car's own definitions of the driver's controls.
pub use autoplug_vehicle::controls::{Button, HeldControls};

/// The session's answer to an [`Action`]: a JSON value, or why it was refused.
pub type Answer = Result<serde_json::Value, String>;

/// A command for the session.
#[derive(Debug)]
pub enum Command {
    /// An action, to be answered.
    Act {
        /// What to do.
        action: Action,
        /// Where the answer goes.
        reply: oneshot::Sender<Answer>,
    },
    /// The person at the wheel moved the controls.
    Drive(HeldControls),
    /// The person pressed a button.
    Press(Button),
    /// The page that drove went away: pedals released.
    DriverLeft,
}

/// The server's end of the queue.
#[derive(Clone, Debug)]
pub struct Control {
    sender: SyncSender<Command>,
}

/// The session's end of the queue.
#[derive(Debug)]
pub struct Commands {
    receiver: Receiver<Command>,
}

/// A queue between the server and the session.
pub fn channel() -> (Control, Commands) {
    let (sender, receiver) = std::sync::mpsc::sync_channel(CONTROL_QUEUE);
    (Control { sender }, Commands { receiver })
}

/// Why a command did not reach the session.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SendError {
    /// The queue is full.
    Busy,
    /// The session has ended.
    Gone,
}

impl Control {
    /// Queues a command without waiting.
    pub fn send(&self, command: Command) -> Result<(), SendError> {
        self.sender.try_send(command).map_err(|e| match e {
            TrySendError::Full(_) => SendError::Busy,
            TrySendError::Disconnected(_) => SendError::Gone,
        })
    }
}

impl Commands {
    /// The next command, if one waits.
    pub fn next(&self) -> Option<Command> {
        // Empty or disconnected: nothing to do either way.
        self.receiver.try_recv().ok()
    }
}

#[cfg(test)]
mod tests {
    use super::ReplayAction;

    fn parse(text: &str) -> Result<ReplayAction, String> {
        serde_json::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn replay_actions_parse_with_their_numbers_and_refuse_what_does_not_fit() {
        assert_eq!(parse(r#"{"action":"play"}"#), Ok(ReplayAction::Play));
        assert_eq!(
            parse(r#"{"action":"seek","t":2.5}"#),
            Ok(ReplayAction::Seek { t: 2.5 })
        );
        assert_eq!(
            parse(r#"{"action":"speed","speed":4}"#),
            Ok(ReplayAction::Speed { speed: 4.0 })
        );
        assert!(parse(r#"{"action":"rewind"}"#)
            .unwrap_err()
            .contains("unknown variant `rewind`"));
        assert!(parse(r#"{"action":"seek"}"#)
            .unwrap_err()
            .contains("missing field `t`"));
        assert!(parse(r#"{"action":"pause","t":1}"#)
            .unwrap_err()
            .contains("unknown field `t`"));
        assert!(parse(r#"{"action":"play","volume":1}"#)
            .unwrap_err()
            .contains("unknown field `volume`"));
    }
}
