//! Reading the ECUs' trouble codes: ReadDTCInformation, reportDTCByStatusMask
//! (`19 02 FF`: every code whatever its status), one ECU after the other, in the default
//! session. The answer (`59 02 mask`, then 3 bytes of code and 1 of status per code) may
//! span several frames; the tester sends their flow control.

use std::fmt::Write as _;

use autoplug_can::Node;
use autoplug_diagnostics::{describe_dtc, DtcEntry};
use autoplug_ecu::Dtc;

use super::job::{EachEcu, EveryEcu, OneRequest};
use super::{Response, TesterConfig, UdsError};
use crate::names::ecu_name;

/// The request: report the codes whose status matches 0xFF (all of them).
pub const REPORT_ALL_DTCS: [u8; 3] = [0x19, 0x02, 0xFF];

/// What one ECU answered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EcuDtcReport {
    /// The ECU.
    pub ecu: Node,
    /// Its codes, or why there are none to show.
    pub entries: Result<Vec<DtcEntry>, UdsError>,
}

/// Parses a positive response `59 02 mask (DTC status)*`.
pub fn parse_report(response: &[u8]) -> Result<Vec<DtcEntry>, UdsError> {
    match response {
        [0x59, 0x02, _mask, records @ ..] if records.len() % 4 == 0 => Ok(records
            .chunks_exact(4)
            .map(|r| DtcEntry {
                dtc: Dtc::from_u24(u32::from_be_bytes([0, r[0], r[1], r[2]])),
                status: r[3],
            })
            .collect()),
        _ => Err(UdsError::UnexpectedResponse {
            service: 0x19,
            response: response.to_vec(),
            expected: "59 02, the availability mask, then 4 bytes per code".into(),
        }),
    }
}

/// Reads the codes of the given ECUs; never fails as a whole: each report says what
/// happened.
pub type DtcJob = EachEcu<EveryEcu<DtcReading>>;

impl DtcJob {
    /// A job reading `ecus` in that order.
    pub fn new(ecus: &[Node], config: TesterConfig) -> Self {
        EachEcu::with(EveryEcu::new(ecus), config)
    }
}

/// The request of a [`DtcJob`]: `19 02 FF`, every code whatever its status.
#[derive(Debug)]
pub struct DtcReading;

impl OneRequest for DtcReading {
    type Report = EcuDtcReport;
    const REQUEST: &'static [u8] = &REPORT_ALL_DTCS;
    const ECHO: usize = 1;

    fn report(ecu: Node, outcome: Result<Response, UdsError>) -> EcuDtcReport {
        let entries = match outcome {
            Ok(Response::Positive(response)) => parse_report(&response),
            Ok(Response::Functional(_)) => Err(UdsError::Busy),
            Err(error) => Err(error),
        };
        EcuDtcReport { ecu, entries }
    }
}

/// The reports as a table: one line per code, with its status and description.
pub fn dtc_table(reports: &[EcuDtcReport]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<13} {:<9} {:>6}  description",
        "ECU", "DTC", "status"
    );
    for report in reports {
        match &report.entries {
            Ok(entries) if entries.is_empty() => {
                let _ = writeln!(out, "{:<13} none", ecu_name(report.ecu));
            }
            Ok(entries) => {
                for e in entries {
                    let _ = writeln!(
                        out,
                        "{:<13} {:<9} {:>6}  {}",
                        ecu_name(report.ecu),
                        e.dtc.to_string(),
                        format!("0x{:02X}", e.status),
                        describe_dtc(e.dtc)
                    );
                }
            }
            Err(error) => {
                let _ = writeln!(
                    out,
                    "{:<13} -         {:>6}  {error}",
                    ecu_name(report.ecu),
                    ""
                );
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_parse_and_refuse_what_is_not_one() {
        let entries = parse_report(&[0x59, 0x02, 0xFF, 0xC1, 0x04, 0x87, 0x2F]).unwrap();
        assert_eq!(entries.len(), 1);
        assert_eq!(entries[0].dtc.to_string(), "U0104-87");
        assert_eq!(entries[0].status, 0x2F);
        assert_eq!(parse_report(&[0x59, 0x02, 0xFF]).unwrap(), vec![]);
        assert!(parse_report(&[0x59, 0x02, 0xFF, 0xC1]).is_err());
        assert!(parse_report(&[0x59, 0x0A, 0xFF]).is_err());
    }
}
