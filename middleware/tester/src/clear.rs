//! Clearing the ECUs' trouble codes: ClearDiagnosticInformation for every group
//! (`14 FF FF FF`, answered `54`), one ECU after the other, in the default session. The
//! ECUs keep only "all groups", so that is what a tester sends.

use std::convert::Infallible;

use autoplug_can::Node;
use autoplug_ecu::Instant;

use super::{Job, Response, Tester, TesterConfig, UdsError};

/// The request: clear the codes of all groups.
pub const CLEAR_ALL_DTCS: [u8; 4] = [0x14, 0xFF, 0xFF, 0xFF];

/// What one ECU answered to the clear.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EcuClearReport {
    /// The ECU.
    pub ecu: Node,
    /// Cleared, or why not.
    pub outcome: Result<(), UdsError>,
}

/// Clears the codes of the given ECUs; never fails as a whole: each report says what
/// happened.
#[derive(Debug)]
pub struct ClearDtcsJob {
    tester: Tester,
    ecus: Vec<Node>,
    next: usize,
    in_flight: bool,
    reports: Vec<EcuClearReport>,
    result: Option<Vec<EcuClearReport>>,
    done: bool,
}

impl ClearDtcsJob {
    /// A job clearing `ecus` in that order.
    pub fn new(ecus: &[Node], config: TesterConfig) -> Self {
        Self {
            tester: Tester::new(config),
            ecus: ecus.to_vec(),
            next: 0,
            in_flight: false,
            reports: Vec::new(),
            result: None,
            done: false,
        }
    }
}

impl Job for ClearDtcsJob {
    type Output = Vec<EcuClearReport>;
    type Error = Infallible;

    fn tester(&self) -> &Tester {
        &self.tester
    }

    fn tester_mut(&mut self) -> &mut Tester {
        &mut self.tester
    }

    fn advance(&mut self, now: Instant) {
        while !self.done {
            if self.in_flight {
                let Some(outcome) = self.tester.take_response() else {
                    return;
                };
                self.in_flight = false;
                let outcome = match outcome {
                    Ok(Response::Positive(response)) if response.first() == Some(&0x54) => Ok(()),
                    Ok(Response::Positive(response)) => Err(UdsError::UnexpectedResponse {
                        service: CLEAR_ALL_DTCS[0],
                        response,
                        expected: "54".into(),
                    }),
                    Ok(Response::Functional(_)) => Err(UdsError::Busy),
                    Err(error) => Err(error),
                };
                self.reports.push(EcuClearReport {
                    ecu: self.ecus[self.next],
                    outcome,
                });
                self.next += 1;
                continue;
            }
            let Some(&ecu) = self.ecus.get(self.next) else {
                self.done = true;
                self.result = Some(std::mem::take(&mut self.reports));
                return;
            };
            match self.tester.request(now, ecu, &CLEAR_ALL_DTCS) {
                Ok(()) => self.in_flight = true,
                Err(error) => {
                    self.reports.push(EcuClearReport {
                        ecu,
                        outcome: Err(error),
                    });
                    self.next += 1;
                }
            }
        }
    }

    fn take_result(&mut self) -> Option<Result<Vec<EcuClearReport>, Infallible>> {
        self.result.take().map(Ok)
    }
}
