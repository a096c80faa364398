//! Service identifiers and negative response codes (ISO 14229-1 annex A.1) used here.

/// Service identifiers of the requests this server answers.
pub mod sid {
    /// DiagnosticSessionControl.
    pub const SESSION_CONTROL: u8 = 0x10;
    /// ECUReset.
    pub const ECU_RESET: u8 = 0x11;
    /// ClearDiagnosticInformation.
    pub const CLEAR_DTC: u8 = 0x14;
    /// ReadDTCInformation.
    pub const READ_DTC: u8 = 0x19;
    /// ReadDataByIdentifier.
    pub const READ_DID: u8 = 0x22;
    /// SecurityAccess.
    pub const SECURITY_ACCESS: u8 = 0x27;
    /// CommunicationControl.
    pub const COMMUNICATION_CONTROL: u8 = 0x28;
    /// RoutineControl.
    pub const ROUTINE_CONTROL: u8 = 0x31;
    /// RequestDownload.
    pub const REQUEST_DOWNLOAD: u8 = 0x34;
    /// TransferData.
    pub const TRANSFER_DATA: u8 = 0x36;
    /// RequestTransferExit.
    pub const REQUEST_TRANSFER_EXIT: u8 = 0x37;
    /// TesterPresent.
    pub const TESTER_PRESENT: u8 = 0x3E;
    /// ControlDTCSetting.
    pub const CONTROL_DTC_SETTING: u8 = 0x85;
    /// The first byte of a negative response.
    pub const NEGATIVE_RESPONSE: u8 = 0x7F;
    /// A positive response's SID is the request's plus this.
    pub const POSITIVE_OFFSET: u8 = 0x40;
}

/// Negative response codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
#[repr(u8)]
pub enum Nrc {
    /// 0x11: the service is not implemented.
    ServiceNotSupported = 0x11,
    /// 0x12: the sub-function is not implemented.
    SubFunctionNotSupported = 0x12,
    /// 0x13: the request is too short, too long, or its length fields disagree.
    IncorrectMessageLengthOrInvalidFormat = 0x13,
    /// 0x14: the response would not fit the transport's 4095 bytes.
    ResponseTooLong = 0x14,
    /// 0x22: not now (the car moves, no download in progress...).
    ConditionsNotCorrect = 0x22,
    /// 0x24: the request comes in the wrong order (a key before a seed, an exit before the
    /// last block...).
    RequestSequenceError = 0x24,
    /// 0x31: a parameter is out of range (unknown identifier, routine, address; an image
    /// for another ECU or older than the floor).
    RequestOutOfRange = 0x31,
    /// 0x33: the service needs security access first.
    SecurityAccessDenied = 0x33,
    /// 0x35: the key is wrong.
    InvalidKey = 0x35,
    /// 0x36: too many wrong keys: locked out for the delay.
    ExceededNumberOfAttempts = 0x36,
    /// 0x37: the lock-out delay has not expired.
    RequiredTimeDelayNotExpired = 0x37,
    /// 0x70: the download is refused (too large for the slot, unsupported format).
    UploadDownloadNotAccepted = 0x70,
    /// 0x71: more data than the download announced.
    TransferDataSuspended = 0x71,
    /// 0x72: erasing, programming or verifying the memory failed (the image does not verify).
    GeneralProgrammingFailure = 0x72,
    /// 0x73: the block sequence counter is neither the next nor the last one.
    WrongBlockSequenceCounter = 0x73,
    /// 0x78: the request is being worked on; the final response follows.
    ResponsePending = 0x78,
    /// 0x7E: the sub-function exists but not in this session.
    SubFunctionNotSupportedInActiveSession = 0x7E,
    /// 0x7F: the service exists but not in this session.
    ServiceNotSupportedInActiveSession = 0x7F,
}

impl Nrc {
    /// The code on the bus.
    pub const fn code(self) -> u8 {
        self as u8
    }
}

impl core::fmt::Display for Nrc {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = match self {
            Nrc::ServiceNotSupported => "service not supported",
            Nrc::SubFunctionNotSupported => "sub-function not supported",
            Nrc::IncorrectMessageLengthOrInvalidFormat => "incorrect message length or format",
            Nrc::ResponseTooLong => "response too long",
            Nrc::ConditionsNotCorrect => "conditions not correct",
            Nrc::RequestSequenceError => "request sequence error",
            Nrc::RequestOutOfRange => "request out of range",
            Nrc::SecurityAccessDenied => "security access denied",
            Nrc::InvalidKey => "invalid key",
            Nrc::ExceededNumberOfAttempts => "exceeded number of attempts",
            Nrc::RequiredTimeDelayNotExpired => "required time delay not expired",
            Nrc::UploadDownloadNotAccepted => "upload/download not accepted",
            Nrc::TransferDataSuspended => "transfer data suspended",
            Nrc::GeneralProgrammingFailure => "general programming failure",
            Nrc::WrongBlockSequenceCounter => "wrong block sequence counter",
            Nrc::ResponsePending => "response pending",
            Nrc::SubFunctionNotSupportedInActiveSession => {
                "sub-function not supported in active session"
            }
            Nrc::ServiceNotSupportedInActiveSession => "service not supported in active session",
        };
        write!(f, "{text} (0x{:02X})", self.code())
    }
}
