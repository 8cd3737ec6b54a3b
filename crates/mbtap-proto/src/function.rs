//! Function codes, exception codes, diagnostic sub-functions and MEI types, with the names the
//! spec gives them. Unknown values stay representable (`Other(u8)`); nothing here can fail.

use std::fmt;

/// Set in the function byte of an exception response (MAP v1.1b3 §7: "function code + 0x80").
pub const EXCEPTION_FLAG: u8 = 0x80;

macro_rules! code_enum {
    (
        $(#[$meta:meta])* $name:ident : $repr:ty {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal, $label:literal ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $name {
            $( $(#[$vmeta])* $variant, )*
            /// A value the spec does not name; kept as it was on the wire.
            Other($repr),
        }

        impl $name {
            /// The value as it travels on the wire.
            #[must_use]
            pub const fn value(self) -> $repr {
                match self {
                    $( Self::$variant => $value, )*
                    Self::Other(v) => v,
                }
            }

            /// The spec's name for this value, `None` for [`Self::Other`].
            #[must_use]
            pub const fn name(self) -> Option<&'static str> {
                match self {
                    $( Self::$variant => Some($label), )*
                    Self::Other(_) => None,
                }
            }
        }

        impl From<$repr> for $name {
            fn from(v: $repr) -> Self {
                match v {
                    $( $value => Self::$variant, )*
                    other => Self::Other(other),
                }
            }
        }

        impl From<$name> for $repr {
            fn from(v: $name) -> Self {
                v.value()
            }
        }
    };
}

code_enum! {
    /// Public function codes (MAP v1.1b3 §5.1, table "Public Function Code Definition").
    FunctionCode: u8 {
        ReadCoils = 0x01, "Read Coils",
        ReadDiscreteInputs = 0x02, "Read Discrete Inputs",
        ReadHoldingRegisters = 0x03, "Read Holding Registers",
        ReadInputRegisters = 0x04, "Read Input Registers",
        WriteSingleCoil = 0x05, "Write Single Coil",
        WriteSingleRegister = 0x06, "Write Single Register",
        /// Serial line only (MAP v1.1b3 §6.7).
        ReadExceptionStatus = 0x07, "Read Exception Status",
        /// Serial line only (MAP v1.1b3 §6.8).
        Diagnostics = 0x08, "Diagnostics",
        GetCommEventCounter = 0x0B, "Get Comm Event Counter",
        GetCommEventLog = 0x0C, "Get Comm Event Log",
        WriteMultipleCoils = 0x0F, "Write Multiple Coils",
        WriteMultipleRegisters = 0x10, "Write Multiple Registers",
        ReportServerId = 0x11, "Report Server ID",
        ReadFileRecord = 0x14, "Read File Record",
        WriteFileRecord = 0x15, "Write File Record",
        MaskWriteRegister = 0x16, "Mask Write Register",
        ReadWriteMultipleRegisters = 0x17, "Read/Write Multiple Registers",
        ReadFifoQueue = 0x18, "Read FIFO Queue",
        EncapsulatedInterface = 0x2B, "Encapsulated Interface Transport",
    }
}

impl FunctionCode {
    /// User-defined function code ranges 65–72 and 100–110 (MAP v1.1b3 §5.1).
    #[must_use]
    pub const fn is_user_defined(self) -> bool {
        matches!(self.value(), 65..=72 | 100..=110)
    }

    /// A name to show: the spec's, "User-defined function" or "Unknown function".
    #[must_use]
    pub const fn label(self) -> &'static str {
        match self.name() {
            Some(n) => n,
            None if self.is_user_defined() => "User-defined function",
            None => "Unknown function",
        }
    }
}

impl fmt::Display for FunctionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:02X} {}", self.value(), self.label())
    }
}

code_enum! {
    /// Exception codes (MAP v1.1b3 §7, "MODBUS Exception Codes"). 07 is from the older
    /// PI-MBUS-300 rev J; 09 is defined by neither and stays `Other(9)`.
    ExceptionCode: u8 {
        IllegalFunction = 0x01, "Illegal Function",
        IllegalDataAddress = 0x02, "Illegal Data Address",
        IllegalDataValue = 0x03, "Illegal Data Value",
        ServerDeviceFailure = 0x04, "Server Device Failure",
        Acknowledge = 0x05, "Acknowledge",
        ServerDeviceBusy = 0x06, "Server Device Busy",
        NegativeAcknowledge = 0x07, "Negative Acknowledge",
        MemoryParityError = 0x08, "Memory Parity Error",
        GatewayPathUnavailable = 0x0A, "Gateway Path Unavailable",
        GatewayTargetFailedToRespond = 0x0B, "Gateway Target Device Failed to Respond",
    }
}

impl fmt::Display for ExceptionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:02X} {}", self.value(), self.name().unwrap_or("Unknown exception"))
    }
}

code_enum! {
    /// Diagnostics (0x08) sub-function codes (MAP v1.1b3 §6.8.1).
    DiagnosticSubFunction: u16 {
        ReturnQueryData = 0x00, "Return Query Data",
        RestartCommunicationsOption = 0x01, "Restart Communications Option",
        ReturnDiagnosticRegister = 0x02, "Return Diagnostic Register",
        ChangeAsciiInputDelimiter = 0x03, "Change ASCII Input Delimiter",
        ForceListenOnlyMode = 0x04, "Force Listen Only Mode",
        ClearCountersAndDiagnosticRegister = 0x0A, "Clear Counters and Diagnostic Register",
        ReturnBusMessageCount = 0x0B, "Return Bus Message Count",
        ReturnBusCommunicationErrorCount = 0x0C, "Return Bus Communication Error Count",
        ReturnBusExceptionErrorCount = 0x0D, "Return Bus Exception Error Count",
        ReturnServerMessageCount = 0x0E, "Return Server Message Count",
        ReturnServerNoResponseCount = 0x0F, "Return Server No Response Count",
        ReturnServerNakCount = 0x10, "Return Server NAK Count",
        ReturnServerBusyCount = 0x11, "Return Server Busy Count",
        ReturnBusCharacterOverrunCount = 0x12, "Return Bus Character Overrun Count",
        ClearOverrunCounterAndFlag = 0x14, "Clear Overrun Counter and Flag",
    }
}

code_enum! {
    /// MEI types carried by function 0x2B (MAP v1.1b3 §6.19–§6.21).
    MeiType: u8 {
        CanopenGeneralReference = 0x0D, "CANopen General Reference",
        ReadDeviceIdentification = 0x0E, "Read Device Identification",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_round_trips_through_function_code() {
        for b in 0..=u8::MAX {
            assert_eq!(FunctionCode::from(b).value(), b);
            assert_eq!(ExceptionCode::from(b).value(), b);
            assert_eq!(MeiType::from(b).value(), b);
        }
    }

    #[test]
    fn unknown_codes_are_kept_not_rejected() {
        assert_eq!(FunctionCode::from(0x41), FunctionCode::Other(0x41));
        assert!(FunctionCode::from(0x41).is_user_defined());
        assert_eq!(FunctionCode::from(0x70).label(), "Unknown function");
        assert_eq!(ExceptionCode::from(9), ExceptionCode::Other(9));
    }

    #[test]
    fn exception_codes_one_to_eleven_are_named_except_nine() {
        for c in 1..=0x0Bu8 {
            assert_eq!(ExceptionCode::from(c).name().is_some(), c != 9, "code {c}");
        }
    }
}
