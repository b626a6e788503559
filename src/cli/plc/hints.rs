//! Failures in the device manual's words, with what to check or try next.
//!
//! A device's refusal keeps the manual's number and meaning (`exception 02 "illegal data
//! address"`) and adds the usual cause on a commissioning day; a timeout says which flag
//! would take the replies that were thrown away (`--ignore-transaction-id`, `--length0`,
//! `--no-pdu-ref`), or, with none, what to check on that kind of link (serial settings and
//! wiring, the unit, the port); a refused connection says that nothing listens there.

use crate::protocols::{DeviceCode, PlcError, Protocol, Quirk, mewtocol, ppi};

/// The flag of `rackd plc` that turns a quirk on.
fn flag(quirk: Quirk) -> String {
    match quirk {
        Quirk::NoTransactionId => "--ignore-transaction-id".into(),
        other => format!("--{other}"),
    }
}

/// A failure in words an operator understands, with a hint where one helps.
pub fn explain(error: &PlcError, protocol: Protocol) -> String {
    match error {
        PlcError::Device(code) => {
            let hint = device_hint(code);
            let words = describe(code);
            if hint.is_empty() { words } else { format!("{words}: {hint}") }
        }
        PlcError::Timeout { attempts, timeout, dropped } => {
            let base = format!("timeout: no reply after {attempts} tries of {} ms", timeout.as_millis());
            match dropped {
                Some(d) => {
                    let text = d.to_string();
                    let what = text.split_once(": the `").map_or(text.as_str(), |(head, _)| head);
                    match d.reason.quirk() {
                        Some(quirk) => format!("{base} ({what}): try {}", flag(quirk)),
                        None => format!("{base} ({what})"),
                    }
                }
                None => format!("{base}: {}", silence_hint(protocol)),
            }
        }
        PlcError::Connection(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
            format!(
                "connection refused: nothing listens there ({e}); check the address and port, and that \
                     the PLC's server or the gateway is on"
            )
        }
        other => other.to_string(),
    }
}

/// What to check when nothing answered at all.
fn silence_hint(protocol: Protocol) -> &'static str {
    match protocol {
        Protocol::ModbusRtu | Protocol::Mewtocol | Protocol::Ppi => {
            "check the unit (--unit), the baud rate and parity (--serial), and the wiring (RS-485 A/B, \
             termination)"
        }
        Protocol::ModbusRtuTcp | Protocol::MewtocolTcp | Protocol::PpiTcp => {
            "check the unit (--unit), the gateway's serial settings (baud rate, parity) and the wiring \
             behind it"
        }
        Protocol::ModbusTcp | Protocol::ModbusUdp => {
            "check the address and port, the unit (--unit: many TCP devices answer only 1, 255 or 0) \
             and, over UDP, that the device speaks Modbus UDP at all"
        }
        Protocol::Mc3e | Protocol::Mc3eUdp | Protocol::Mc4e | Protocol::Mc4eUdp => {
            "check the port and the transport against the module's open settings (TCP or UDP, \
             binary code), and that the port is open for MC protocol"
        }
    }
}

/// The device's code as its manual writes it.
pub fn describe(code: &DeviceCode) -> String {
    match code {
        DeviceCode::Modbus(e) => format!("exception {:02X} \"{}\"", e.0, e.meaning()),
        DeviceCode::Mc3e(c) => format!("end code {:04X} \"{}\"", c.0, c.meaning()),
        DeviceCode::Mewtocol(c) => format!("error {:02} \"{}\"", c.0, c.meaning()),
        DeviceCode::Ppi(c @ ppi::ReturnCode::Refused { class, code }) => {
            format!("request refused, error class {class:02X} code {code:02X} \"{}\"", c.meaning())
        }
        DeviceCode::Ppi(c @ ppi::ReturnCode::Item(code)) => {
            format!("item return code {code:02X} \"{}\"", c.meaning())
        }
    }
}

/// The usual cause of a device's refusal, where there is one to name.
fn device_hint(code: &DeviceCode) -> &'static str {
    match code {
        DeviceCode::Modbus(e) => match e.0 {
            1 => {
                "the device does not offer this function for this table (some have no coils or input registers)"
            }
            2 => {
                "the address is outside the device's map; check the notation too: 4x100 is PDU address 100, \
                  Modicon 40101"
            }
            3 => "check the count (at most 125 registers or 2000 bits per read) and the value",
            0x0A | 0x0B => "the gateway cannot reach the unit: check --unit and the gateway's serial side",
            _ => "",
        },
        DeviceCode::Mc3e(c) => match c.0 {
            0xC051..=0xC054 => "ask for fewer points (COUNT)",
            0xC056 => "the device number is beyond the CPU's device range (set in the PLC parameters)",
            0xC059 | 0xC05C | 0xC072 => "this CPU or module does not take that request for that device",
            0xC05E => "the CPU was too slow for the monitoring timer: raise --timeout-ms",
            0xC06F => "the port is set to ASCII code: rackd speaks binary (set binary in the open settings)",
            _ => "",
        },
        DeviceCode::Mewtocol(c) => match c.0 {
            mewtocol::error_code::BCC_ERROR => {
                "the PLC has a BCC check rackd did not match; try --no-bcc if it \
                                                is set without one"
            }
            mewtocol::error_code::NOT_SUPPORTED => "this PLC does not know the command",
            mewtocol::error_code::PARAMETER_ERROR => "check the address range of this PLC type",
            mewtocol::error_code::MODE_ERROR => "the PLC refuses writes in its current mode (PROG/RUN)",
            _ => "",
        },
        DeviceCode::Ppi(c) => match c {
            ppi::ReturnCode::Item(ppi::return_code::OUT_OF_RANGE) => {
                "the address is beyond this CPU's memory (V memory size differs by CPU)"
            }
            ppi::ReturnCode::Item(ppi::return_code::ACCESS_DENIED) => {
                "the CPU protects this area (password?)"
            }
            _ => "",
        },
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::protocols::{DropReason, Dropped};

    fn timeout(reason: Option<DropReason>) -> PlcError {
        let dropped = reason.map(|reason| Dropped { count: 2, reason });
        PlcError::Timeout { attempts: 3, timeout: Duration::from_millis(200), dropped }
    }

    #[test]
    fn a_timeout_names_the_flag_that_takes_the_dropped_replies() {
        assert_eq!(
            explain(&timeout(Some(DropReason::TransactionId)), Protocol::ModbusTcp),
            "timeout: no reply after 3 tries of 200 ms (2 replies arrived with another transaction id): \
             try --ignore-transaction-id"
        );
        let length0 = explain(&timeout(Some(DropReason::LengthZero)), Protocol::ModbusUdp);
        assert!(length0.ends_with("with MBAP length 0): try --length0"), "{length0}");
        let pdu = explain(&timeout(Some(DropReason::PduReference)), Protocol::PpiTcp);
        assert!(pdu.ends_with("try --no-pdu-ref"), "{pdu}");
        let unit = explain(&timeout(Some(DropReason::Unit)), Protocol::ModbusRtu);
        assert!(unit.ends_with("(2 replies arrived from another unit)"), "{unit}");
    }

    #[test]
    fn silence_on_a_serial_line_names_unit_baud_parity_and_wiring() {
        for protocol in [Protocol::ModbusRtu, Protocol::Mewtocol, Protocol::Ppi] {
            let text = explain(&timeout(None), protocol);
            assert!(
                text.contains("--unit") && text.contains("baud rate and parity") && text.contains("wiring")
            );
        }
        assert!(explain(&timeout(None), Protocol::ModbusTcp).contains("255"));
    }

    #[test]
    fn device_codes_keep_the_manuals_words_and_add_what_to_check() {
        let e: PlcError = crate::protocols::modbus::Exception(2).into();
        let text = explain(&e, Protocol::ModbusTcp);
        assert!(text.starts_with("exception 02 \"illegal data address\": "), "{text}");
        assert!(text.contains("40101"), "{text}");
        assert_eq!(
            explain(&mewtocol::error_code::device_error(63), Protocol::Mewtocol),
            "error 63 \"PLC mode error\": the PLC refuses writes in its current mode (PROG/RUN)"
        );
        assert_eq!(
            explain(&ppi::return_code::item_error(0x0A), Protocol::Ppi),
            "item return code 0A \"object does not exist\""
        );
        assert_eq!(
            explain(&ppi::return_code::refused(0x85, 0), Protocol::Ppi),
            "request refused, error class 85 code 00 \"error on supplies (request refused)\""
        );
        let refused = std::io::Error::from(std::io::ErrorKind::ConnectionRefused);
        assert!(explain(&PlcError::Connection(refused), Protocol::Mc3e).contains("nothing listens"));
    }
}
