//! Serial line settings in the usual `9600,8E1` notation (baud, data bits, parity N/E/O,
//! stop bits), shared by every serial protocol (Modbus RTU, MEWTOCOL, PPI).

use std::str::FromStr;

use tokio_serial::{DataBits, Parity, SerialPortBuilderExt, SerialStream, StopBits};

/// Baud rate, character format and parity of a serial line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SerialSettings {
    /// Bits per second.
    pub baud: u32,
    /// Data bits per character.
    pub data_bits: DataBits,
    /// Parity bit.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: StopBits,
}

impl Default for SerialSettings {
    /// 9600,8E1: the Modbus RTU default (even parity).
    fn default() -> Self {
        SerialSettings {
            baud: 9600,
            data_bits: DataBits::Eight,
            parity: Parity::Even,
            stop_bits: StopBits::One,
        }
    }
}

/// Why a serial settings string was rejected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("bad serial settings {text:?}: {reason} (expected e.g. 9600,8E1)")]
pub struct SerialSettingsError {
    /// The text as given.
    pub text: String,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl FromStr for SerialSettings {
    type Err = SerialSettingsError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let bad = |reason| SerialSettingsError { text: text.to_string(), reason };
        let (baud, format) = text.trim().split_once(',').ok_or_else(|| bad("missing ','"))?;
        let baud: u32 = baud.trim().parse().map_err(|_| bad("the baud rate must be a number"))?;
        if baud == 0 {
            return Err(bad("the baud rate must not be 0"));
        }
        let f = format.trim().as_bytes();
        if f.len() != 3 {
            return Err(bad("the format must be three characters: data bits, parity, stop bits"));
        }
        let data_bits = match f[0] {
            b'5' => DataBits::Five,
            b'6' => DataBits::Six,
            b'7' => DataBits::Seven,
            b'8' => DataBits::Eight,
            _ => return Err(bad("data bits must be 5..8")),
        };
        let parity = match f[1].to_ascii_uppercase() {
            b'N' => Parity::None,
            b'E' => Parity::Even,
            b'O' => Parity::Odd,
            _ => return Err(bad("parity must be N, E or O")),
        };
        let stop_bits = match f[2] {
            b'1' => StopBits::One,
            b'2' => StopBits::Two,
            _ => return Err(bad("stop bits must be 1 or 2")),
        };
        Ok(SerialSettings { baud, data_bits, parity, stop_bits })
    }
}

impl std::fmt::Display for SerialSettings {
    /// The `9600,8E1` notation [`FromStr`] reads.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let data = match self.data_bits {
            DataBits::Five => 5,
            DataBits::Six => 6,
            DataBits::Seven => 7,
            DataBits::Eight => 8,
        };
        let parity = match self.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        let stop = if self.stop_bits == StopBits::Two { 2 } else { 1 };
        write!(f, "{},{data}{parity}{stop}", self.baud)
    }
}

impl SerialSettings {
    /// Opens the serial port at `path` with these settings.
    pub fn open(&self, path: &str) -> std::io::Result<SerialStream> {
        tokio_serial::new(path, self.baud)
            .data_bits(self.data_bits)
            .parity(self.parity)
            .stop_bits(self.stop_bits)
            .open_native_async()
            .map_err(std::io::Error::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_common_settings() {
        let s: SerialSettings = "9600,8E1".parse().unwrap();
        assert_eq!(s, SerialSettings::default());
        let s: SerialSettings = "19200,7o2".parse().unwrap();
        assert_eq!(
            (s.baud, s.data_bits, s.parity, s.stop_bits),
            (19200, DataBits::Seven, Parity::Odd, StopBits::Two)
        );
        assert_eq!("115200,8N1".parse::<SerialSettings>().unwrap().parity, Parity::None);
        for text in ["9600,8E1", "19200,7O2", "187500,8N1", "300,5E1"] {
            assert_eq!(text.parse::<SerialSettings>().unwrap().to_string(), text, "round trip");
        }
    }

    #[test]
    fn rejects_bad_settings() {
        for text in
            ["", "9600", "9600,8E", "9600,9E1", "9600,8X1", "9600,8E3", "fast,8E1", "0,8N1", "9600,8E1x"]
        {
            assert!(text.parse::<SerialSettings>().is_err(), "{text}");
        }
    }
}
