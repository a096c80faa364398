//! Names for what crosses the bus: negative response codes and services as ISO 14229-1
//! spells them, and the ECUs as the command line spells them.
//!
//! An error that says `0x72` makes the user look it up; one that says
//! `generalProgrammingFailure` does not. The names are ISO 14229-1's own (annex A.1), so
//! they can be searched for in the standard and in other tools' logs.

use std::fmt;

use autoplug_can::Node;

/// The ISO 14229-1 name of a negative response code (annex A.1), e.g.
/// `nrc_name(0x70) == "uploadDownloadNotAccepted"`. Codes the standard reserves or leaves
/// to the manufacturer get the name of their range.
pub fn nrc_name(nrc: u8) -> &'static str {
    match nrc {
        0x00 => "positiveResponse",
        0x10 => "generalReject",
        0x11 => "serviceNotSupported",
        0x12 => "subFunctionNotSupported",
        0x13 => "incorrectMessageLengthOrInvalidFormat",
        0x14 => "responseTooLong",
        0x21 => "busyRepeatRequest",
        0x22 => "conditionsNotCorrect",
        0x24 => "requestSequenceError",
        0x25 => "noResponseFromSubnetComponent",
        0x26 => "failurePreventsExecutionOfRequestedAction",
        0x31 => "requestOutOfRange",
        0x33 => "securityAccessDenied",
        0x34 => "authenticationRequired",
        0x35 => "invalidKey",
        0x36 => "exceedNumberOfAttempts",
        0x37 => "requiredTimeDelayNotExpired",
        0x38..=0x4F => "reservedByExtendedDataLinkSecurityDocument",
        0x70 => "uploadDownloadNotAccepted",
        0x71 => "transferDataSuspended",
        0x72 => "generalProgrammingFailure",
        0x73 => "wrongBlockSequenceCounter",
        0x78 => "requestCorrectlyReceivedResponsePending",
        0x7E => "subFunctionNotSupportedInActiveSession",
        0x7F => "serviceNotSupportedInActiveSession",
        0x81 => "rpmTooHigh",
        0x82 => "rpmTooLow",
        0x83 => "engineIsRunning",
        0x84 => "engineIsNotRunning",
        0x85 => "engineRunTimeTooLow",
        0x86 => "temperatureTooHigh",
        0x87 => "temperatureTooLow",
        0x88 => "vehicleSpeedTooHigh",
        0x89 => "vehicleSpeedTooLow",
        0x8A => "throttlePedalTooHigh",
        0x8B => "throttlePedalTooLow",
        0x8C => "transmissionRangeNotInNeutral",
        0x8D => "transmissionRangeNotInGear",
        0x8F => "brakeSwitchesNotClosed",
        0x90 => "shifterLeverNotInPark",
        0x91 => "torqueConverterClutchLocked",
        0x92 => "voltageTooHigh",
        0x93 => "voltageTooLow",
        0x94 => "resourceTemporarilyNotAvailable",
        0xF0..=0xFE => "vehicleManufacturerSpecificConditionsNotCorrect",
        _ => "ISOSAEReserved",
    }
}

/// The ISO 14229-1 name of a request service identifier, e.g. `service_name(0x34) ==
/// "RequestDownload"`; `"unknown service"` for one this tool does not use.
pub fn service_name(service: u8) -> &'static str {
    match service {
        0x10 => "DiagnosticSessionControl",
        0x11 => "ECUReset",
        0x14 => "ClearDiagnosticInformation",
        0x19 => "ReadDTCInformation",
        0x22 => "ReadDataByIdentifier",
        0x27 => "SecurityAccess",
        0x28 => "CommunicationControl",
        0x2E => "WriteDataByIdentifier",
        0x31 => "RoutineControl",
        0x34 => "RequestDownload",
        0x36 => "TransferData",
        0x37 => "RequestTransferExit",
        0x3E => "TesterPresent",
        0x85 => "ControlDTCSetting",
        _ => "unknown service",
    }
}

pub use autoplug_can::{ecu_name, ECUS, ECU_NAME_LIST};

/// A name that is not one of the ECUs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownEcu(pub String);

impl fmt::Display for UnknownEcu {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown ECU '{}': expected one of {ECU_NAME_LIST}",
            self.0
        )
    }
}

impl std::error::Error for UnknownEcu {}

/// The ECU called `name` on the command line (case-insensitive, aliases `trans` and
/// `diff`).
pub fn parse_ecu(name: &str) -> Result<Node, UnknownEcu> {
    autoplug_can::parse_ecu(name).ok_or_else(|| UnknownEcu(name.to_string()))
}

/// `cruise (0x0D)`: how reports and errors name an ECU.
pub fn ecu_label(node: Node) -> String {
    match node.diag_node_number() {
        Some(number) => format!("{} (0x{number:02X})", ecu_name(node)),
        None => ecu_name(node).to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nrc_names_follow_iso_14229() {
        assert_eq!(nrc_name(0x22), "conditionsNotCorrect");
        assert_eq!(nrc_name(0x31), "requestOutOfRange");
        assert_eq!(nrc_name(0x70), "uploadDownloadNotAccepted");
        assert_eq!(nrc_name(0x72), "generalProgrammingFailure");
        assert_eq!(nrc_name(0x78), "requestCorrectlyReceivedResponsePending");
        assert_eq!(nrc_name(0x40), "reservedByExtendedDataLinkSecurityDocument");
        assert_eq!(
            nrc_name(0xF3),
            "vehicleManufacturerSpecificConditionsNotCorrect"
        );
        assert_eq!(nrc_name(0x60), "ISOSAEReserved");
        // Every NRC the ECUs of this project send has a name of its own.
        for code in [
            0x11, 0x12, 0x13, 0x14, 0x22, 0x24, 0x31, 0x33, 0x35, 0x36, 0x37, 0x70, 0x71, 0x72,
            0x73, 0x78, 0x7E, 0x7F,
        ] {
            assert_ne!(nrc_name(code), "ISOSAEReserved", "0x{code:02X}");
        }
    }

    #[test]
    fn ecu_names_and_aliases() {
        assert_eq!(parse_ecu("cruise"), Ok(Node::Cruise));
        assert_eq!(parse_ecu("ABS"), Ok(Node::ABS));
        assert_eq!(parse_ecu("trans"), Ok(Node::Transmission));
        assert_eq!(parse_ecu("diff"), Ok(Node::Differential));
        let error = parse_ecu("gateway").unwrap_err().to_string();
        assert!(error.contains("unknown ECU 'gateway'"), "{error}");
        assert!(error.contains("differential, cruise, abs"), "{error}");
        for node in ECUS {
            assert_eq!(parse_ecu(ecu_name(node)), Ok(node));
            assert!(node.diag_request_id().is_some());
        }
        assert_eq!(ecu_label(Node::Cruise), "cruise (0x0D)");
    }
}
