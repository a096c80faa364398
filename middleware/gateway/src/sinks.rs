//! Observers that write what the pipeline sees.

use std::time::Instant;

use autoplug_logs::{LogFrame, RecordError, RecordSummary, Recorder};

use crate::pipeline::Observer;
use crate::state::{CarState, Update};

/// Records every frame the pipeline sees with an [`autoplug_logs::Recorder`] (candump
/// files, rotated, flushed every 100 ms). A write failure (a full disk) stops the
/// recording and keeps the error for the caller to report; the pipeline, and with it the
/// diagnostics and trips, goes on.
pub struct RecordingSink {
    recorder: Option<Recorder>,
    failure: Option<RecordError>,
    summary: RecordSummary,
}

impl RecordingSink {
    /// Records with this recorder.
    pub fn new(recorder: Recorder) -> Self {
        Self {
            recorder: Some(recorder),
            failure: None,
            summary: RecordSummary::default(),
        }
    }

    /// Whether it is still recording.
    pub fn is_recording(&self) -> bool {
        self.recorder.is_some()
    }

    /// What it has written so far, and the file it writes now (none once stopped).
    pub fn written(&self) -> (RecordSummary, Option<std::path::PathBuf>) {
        match &self.recorder {
            Some(recorder) => (
                recorder.summary().clone(),
                recorder.current_file().map(|p| p.to_path_buf()),
            ),
            None => (self.summary.clone(), None),
        }
    }

    /// Why the recording stopped early, if it did.
    pub fn failure(&self) -> Option<&RecordError> {
        self.failure.as_ref()
    }

    /// Stops the recording (flushing and syncing its file) and says what it wrote.
    pub fn stop(&mut self) -> Result<RecordSummary, RecordError> {
        match self.recorder.take() {
            Some(recorder) => {
                let summary = recorder.stop()?;
                self.summary = summary.clone();
                Ok(summary)
            }
            None => Ok(self.summary.clone()),
        }
    }

    fn fail(&mut self, error: RecordError) {
        if let Some(recorder) = self.recorder.take() {
            self.summary = recorder.summary().clone();
        }
        self.failure = Some(error);
    }
}

impl Observer for RecordingSink {
    fn on_frame(&mut self, frame: &LogFrame, _update: Update, _state: &CarState) {
        if let Some(recorder) = self.recorder.as_mut() {
            if let Err(error) = recorder.write(frame) {
                self.fail(error);
            }
        }
    }

    fn on_idle(&mut self, _state: &CarState) {
        if let Some(recorder) = self.recorder.as_mut() {
            if let Err(error) = recorder.poll(Instant::now()) {
                self.fail(error);
            }
        }
    }
}
