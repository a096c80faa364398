//! Clearing the ECUs' trouble codes: ClearDiagnosticInformation for every group
//! (`14 FF FF FF`, answered `54`), one ECU after the other, in the default session. The
//! ECUs keep only "all groups", so that is what a tester sends.

use autoplug_can::Node;

use super::job::{EachEcu, EveryEcu, OneRequest};
use super::{Response, TesterConfig, UdsError};

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
pub type ClearDtcsJob = EachEcu<EveryEcu<Clearing>>;

impl ClearDtcsJob {
    /// A job clearing `ecus` in that order.
    pub fn new(ecus: &[Node], config: TesterConfig) -> Self {
        EachEcu::with(EveryEcu::new(ecus), config)
    }
}

/// The request of a [`ClearDtcsJob`]: `14 FF FF FF`, answered `54`.
#[derive(Debug)]
pub struct Clearing;

impl OneRequest for Clearing {
    type Report = EcuClearReport;
    const REQUEST: &'static [u8] = &CLEAR_ALL_DTCS;
    const ECHO: usize = 0;

    fn report(ecu: Node, outcome: Result<Response, UdsError>) -> EcuClearReport {
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
        EcuClearReport { ecu, outcome }
    }
}
