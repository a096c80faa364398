//! Is the bus an AutoPlug car at all? Judged from the bus alone, before any ECU is: a log
//! of another vehicle that happens to use an identifier of the catalogue (0x00E is a
//! common one) would otherwise have that message's ECU judged on someone else's data.
//!
//! Each data frame is the catalogue's, foreign, or neutral:
//! - the catalogue's: a catalogue message at the catalogue's length;
//! - foreign: a standard identifier the catalogue does not know, a catalogue identifier at
//!   another length, an extended identifier (the AutoPlug bus uses 11-bit ones only), or a
//!   CAN FD frame (the AutoPlug bus is classic CAN);
//! - neutral: diagnostic traffic, the catalogue's own and any tester's (the OBD-II and UDS
//!   identifiers of ISO 15765-4, 0x7DF and 0x7E0 to 0x7EF: a scan tool talks to any car),
//!   and remote and error frames.
//!
//! The bus is not an AutoPlug car when:
//! - more than [`FOREIGN_SHARE_MAX`] (20 %) of its catalogue and foreign frames are
//!   foreign. Every log the project writes has none; another car's bus is almost all
//!   foreign (tens of identifiers, a few of which may be the catalogue's), and 20 % leaves
//!   room for a device or two beside an AutoPlug car on a bench; or
//! - fewer than [`MIN_MESSAGES_SEEN`] (half) of the catalogue's messages were seen at their
//!   length in a log of at least [`MIN_SPAN_US`] (1 s) of bus time. Every catalogue message
//!   comes at least every 100 ms, so in 1 s an AutoPlug car shows all of them; a silenced
//!   ECU takes at most 3 of 18 away. A shorter log is not judged on this: it may simply
//!   have ended before the slower messages came.
//!
//! A log with too little traffic to say either is taken as an AutoPlug car: nothing on it
//! says otherwise.

use autoplug_can::MESSAGES;
use autoplug_gateway::Update;
use autoplug_logs::{FrameKind, LogFrame};
use serde::Serialize;

/// Foreign frames above this share of the catalogue's and foreign ones: another car.
pub const FOREIGN_SHARE_MAX: f64 = 0.2;
/// The catalogue's messages a log of [`MIN_SPAN_US`] or more must show: half of them.
pub const MIN_MESSAGES_SEEN: usize = MESSAGES.len() / 2;
/// Bus time from which missing catalogue messages count, µs: 10 periods of the slowest.
pub const MIN_SPAN_US: u64 = 1_000_000;

/// Whether a standard identifier is a tester's (OBD-II and UDS on CAN, ISO 15765-4).
fn is_tester_id(id: u32) -> bool {
    id == 0x7DF || (0x7E0..=0x7EF).contains(&id)
}

/// The tallies the recognition is made of, kept frame by frame.
#[derive(Clone, Debug)]
pub struct BusTally {
    catalogue_frames: u64,
    foreign_frames: u64,
    /// Each catalogue message seen at its length, as in [`MESSAGES`].
    seen: [bool; MESSAGES.len()],
    first_us: Option<u64>,
    last_us: Option<u64>,
}

impl Default for BusTally {
    fn default() -> Self {
        Self {
            catalogue_frames: 0,
            foreign_frames: 0,
            seen: [false; MESSAGES.len()],
            first_us: None,
            last_us: None,
        }
    }
}

impl BusTally {
    /// A frame, as the car state classified it.
    pub fn note(&mut self, frame: &LogFrame, update: Update) {
        self.first_us = Some(self.first_us.map_or(frame.t_us, |t| t.min(frame.t_us)));
        self.last_us = Some(self.last_us.map_or(frame.t_us, |t| t.max(frame.t_us)));
        match update {
            Update::Message { index, .. } => {
                self.catalogue_frames += 1;
                self.seen[index] = true;
            }
            Update::WrongLength => self.foreign_frames += 1,
            Update::Diagnostic | Update::Error => {}
            Update::Other => {
                let neutral =
                    frame.kind != FrameKind::Data || (!frame.extended && is_tester_id(frame.id));
                if !neutral {
                    self.foreign_frames += 1;
                }
            }
        }
    }

    /// The judgement on what was seen so far.
    pub fn recognition(&self) -> Recognition {
        let judged = self.catalogue_frames + self.foreign_frames;
        let foreign_share = if judged == 0 {
            0.0
        } else {
            self.foreign_frames as f64 / judged as f64
        };
        let messages_seen = self.seen.iter().filter(|&&s| s).count();
        let span_us = match (self.first_us, self.last_us) {
            (Some(first), Some(last)) => last - first,
            _ => 0,
        };
        let mut reasons = Vec::new();
        if foreign_share > FOREIGN_SHARE_MAX {
            reasons.push(format!(
                "{:.1} % of its {judged} data frames have an identifier or a length the catalogue does not know (above {:.0} %)",
                foreign_share * 100.0,
                FOREIGN_SHARE_MAX * 100.0
            ));
        }
        if span_us >= MIN_SPAN_US && messages_seen < MIN_MESSAGES_SEEN {
            reasons.push(format!(
                "only {messages_seen} of the catalogue's {} messages in {:.1} s (fewer than {MIN_MESSAGES_SEEN})",
                MESSAGES.len(),
                span_us as f64 * 1e-6
            ));
        }
        Recognition {
            autoplug: reasons.is_empty(),
            catalogue_frames: self.catalogue_frames,
            foreign_frames: self.foreign_frames,
            foreign_share,
            messages_seen,
            catalogue_messages: MESSAGES.len(),
            bus_time_s: span_us as f64 * 1e-6,
            reasons,
        }
    }
}

/// Whether the bus is an AutoPlug car, and the figures that say so.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Recognition {
    /// An AutoPlug car: nothing on the bus says otherwise.
    pub autoplug: bool,
    /// Catalogue messages at the catalogue's length.
    pub catalogue_frames: u64,
    /// Data frames the catalogue does not know (identifier, length, or extended).
    pub foreign_frames: u64,
    /// Foreign frames among the catalogue's and foreign ones, 0 to 1.
    pub foreign_share: f64,
    /// Catalogue messages seen at least once at their length.
    pub messages_seen: usize,
    /// Messages in the catalogue.
    pub catalogue_messages: usize,
    /// Bus time from the first frame to the last, s.
    pub bus_time_s: f64,
    /// Why it is not an AutoPlug car (empty when it is).
    pub reasons: Vec<String>,
}

impl Recognition {
    /// One line for people: `an AutoPlug car (18 of the catalogue's 18 messages, 0.0 % of
    /// 9741 data frames foreign)` or `not an AutoPlug car: <reasons>`.
    pub fn summary(&self) -> String {
        if self.autoplug {
            format!(
                "an AutoPlug car ({} of the catalogue's {} messages, {:.1} % of {} data frames foreign)",
                self.messages_seen,
                self.catalogue_messages,
                self.foreign_share * 100.0,
                self.catalogue_frames + self.foreign_frames
            )
        } else {
            format!("not an AutoPlug car: {}", self.reasons.join("; "))
        }
    }
}
