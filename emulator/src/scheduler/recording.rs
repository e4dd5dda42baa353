//! The recording stage: one log record a cycle, through the recorder's bounded channel
//! (a copy, no allocation). A writer that fails (a full disk) ends the run like any
//! abort, and is not written to again.

use super::Abort;
use crate::plant::{ActuatorCommand, Plant};
use crate::recorder::{Record, Recorder, StepTimes, REC_ENDED_AFTER_PUBLISH, REC_END_OF_RUN};
use oils_shared::{Command, Telemetry};

/// The run's log, while it takes records.
pub(super) struct Recording<'a> {
    recorder: Option<&'a Recorder>,
}

impl<'a> Recording<'a> {
    pub(super) fn new(recorder: Option<&'a Recorder>) -> Self {
        Self { recorder }
    }

    /// The cycle `k`'s record: what went out, what came back, what the plant holds.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record(
        &mut self,
        k: u64,
        flags: u32,
        telemetry: &Telemetry,
        command: Option<Command>,
        applied: &ActuatorCommand,
        plant: &Plant,
        faults_active: u64,
        timing: StepTimes,
    ) -> Result<(), Abort> {
        let Some(r) = self.recorder else {
            return Ok(());
        };
        let logged = r.record(&Record {
            flags,
            telemetry: *telemetry,
            command: command.unwrap_or_default(),
            applied: *applied,
            truth: plant.truth(),
            faults_active,
            timing,
        });
        if logged.is_err() {
            self.recorder = None;
            return Err(Abort::LogFailed { step: k });
        }
        Ok(())
    }

    /// The end-of-run record. `after_publish`: the last telemetry went out mid-step
    /// before the end (a replay must know). Best effort: a failed writer already ended
    /// the run.
    pub(super) fn record_end(
        &self,
        flags: u32,
        after_publish: bool,
        telemetry: &Telemetry,
        plant: &Plant,
        faults_active: u64,
        timing: StepTimes,
    ) {
        if let Some(r) = self.recorder {
            let after = if after_publish {
                REC_ENDED_AFTER_PUBLISH
            } else {
                0
            };
            let _ = r.record(&Record {
                flags: REC_END_OF_RUN | after | flags,
                telemetry: *telemetry,
                command: Command::default(),
                applied: ActuatorCommand::default(),
                truth: plant.truth(),
                faults_active,
                timing,
            });
        }
    }
}
