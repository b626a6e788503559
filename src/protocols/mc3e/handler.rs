//! What the simulated PLC answers to one request frame: pure, no I/O, never panics.
//!
//! Refusals, in the order they are checked: not a 3E request (no answer), a request too
//! short to carry its command (C061 without error information), an unsupported command or
//! subcommand (C059), a request whose data length disagrees with its point count (C061), an
//! unknown device code (C05B), bit units on a word device (C05C), a bit value other than 0
//! or 1 (C060), a point count of 0 or above 960 words / 7168 bits (C051, the code the
//! seed's crane answers to an over-long read), and a range past the device's end (C056).
//! Random reads past 192 points and block reads past 120 blocks or 960 words answer C051;
//! a bit device among the word blocks of a block read (or the reverse) C05C.
//!
//! 3E and 4E requests are answered on the same port, each in its own frame: a 4E reply
//! echoes the request's serial number. "Read CPU model name" answers the configured
//! [`TypeName`].

use std::sync::{Arc, Mutex};

use super::bank::Bank;
use super::device::Device;
use super::end_code;
use super::frame::{self, FrameError, MAX_BIT_POINTS, MAX_WORD_POINTS};
use super::request::{Command, Refusal, Request, RequestHeader};
use super::response::{ErrorInfo, Outcome, Response};
use super::type_name::TypeName;

/// A write the server carried out, reported to the write hook.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteEvent {
    /// The device written.
    pub device: Device,
    /// The first device number written.
    pub start: u32,
    /// The number of points (bits of a bit device, words of a word device).
    pub points: u32,
}

/// Called after every successful write, with the bank unlocked (a simulator reacting to
/// the host's writes, such as a crane seeing its strobe set).
pub type WriteHook = Arc<dyn Fn(WriteEvent) + Send + Sync>;

/// The answer to one frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Answer {
    /// The response bytes.
    pub bytes: Vec<u8>,
    /// The write carried out, if any.
    pub write: Option<WriteEvent>,
}

/// Answers one request frame against `bank` (and `type_name` to "read CPU model name");
/// `forced` replaces execution with that end code. `None` means the bytes are not a 3E or
/// 4E binary request and deserve no answer.
pub fn answer(bank: &Mutex<Bank>, type_name: &TypeName, bytes: &[u8], forced: Option<u16>) -> Option<Answer> {
    let refuse = |header: &RequestHeader, code: u16| Answer {
        bytes: error_response(header.serial, header.route, code, Some((header.command, header.subcommand))),
        write: None,
    };
    let request = match Request::decode(bytes) {
        Ok(request) => request,
        Err(Refusal::Command { header, end_code }) => return Some(refuse(&header, end_code)),
        Err(Refusal::Frame(FrameError::Subheader(_))) => return None,
        Err(Refusal::Frame(_)) => {
            // A 3E/4E header whose length or body is short: answer if the route is readable.
            let header = frame::parse_any_header(bytes, frame::Direction::Request).ok()?;
            return Some(Answer {
                bytes: error_response(header.serial, header.route, end_code::LENGTH_MISMATCH, None),
                write: None,
            });
        }
    };
    let (command, subcommand) = request.command.numbers();
    let fail = |code| Answer {
        bytes: error_response(request.serial, request.route, code, Some((command, subcommand))),
        write: None,
    };
    if let Some(code) = forced {
        return Some(fail(code));
    }
    let ok = |data, write| Answer {
        bytes: Response { serial: request.serial, route: request.route, outcome: Outcome::Ok(data) }.encode(),
        write,
    };
    let mut bank = match bank.lock() {
        Ok(bank) => bank,
        Err(poisoned) => poisoned.into_inner(),
    };
    let result = match &request.command {
        Command::ReadWords { device, start, count } => check_count(*count, MAX_WORD_POINTS)
            .and_then(|_| bank.read_words(*device, *start, *count))
            .map(|w| (w.iter().flat_map(|v| v.to_le_bytes()).collect(), None)),
        Command::ReadBits { device, start, count } => check_count(*count, MAX_BIT_POINTS)
            .and_then(|_| bank.read_bits(*device, *start, *count))
            .map(|bits| {
                let mut data = Vec::with_capacity(frame::bit_bytes(bits.len()));
                frame::pack_bits(&bits, &mut data);
                (data, None)
            }),
        Command::WriteWords { device, start, values } => check_count(values.len() as u16, MAX_WORD_POINTS)
            .and_then(|_| bank.write_words(*device, *start, values))
            .map(|_| {
                let unit = if device.is_bit() { 16 } else { 1 };
                let points = values.len() as u32 * unit;
                (vec![], Some(WriteEvent { device: *device, start: *start, points }))
            }),
        Command::WriteBits { device, start, values } => check_count(values.len() as u16, MAX_BIT_POINTS)
            .and_then(|_| bank.write_bits(*device, *start, values))
            .map(|_| {
                (vec![], Some(WriteEvent { device: *device, start: *start, points: values.len() as u32 }))
            }),
        Command::ReadTypeName => Ok((type_name.encode(), None)),
        Command::RandomRead { .. } | Command::ReadBlocks { .. } => read_scattered(&bank, &request.command),
    };
    Some(match result {
        Ok((data, write)) => ok(data, write),
        Err(code) => fail(code),
    })
}

/// Random and block reads: the words of each device or block, in request order.
fn read_scattered(bank: &Bank, command: &Command) -> Result<(Vec<u8>, Option<WriteEvent>), u16> {
    if let Some(code) = command.refusal() {
        return Err(code);
    }
    let runs: Vec<(Device, u32, u16)> = match command {
        Command::RandomRead { words, dwords } => {
            words.iter().map(|&(d, n)| (d, n, 1)).chain(dwords.iter().map(|&(d, n)| (d, n, 2))).collect()
        }
        Command::ReadBlocks { words, bits } => {
            words.iter().chain(bits).map(|b| (b.device, b.start, b.points)).collect()
        }
        _ => Vec::new(),
    };
    let mut data = Vec::with_capacity(command.reply_data_len());
    for (device, start, count) in runs {
        let words = bank.read_words(device, start, count)?;
        data.extend(words.iter().flat_map(|w| w.to_le_bytes()));
    }
    Ok((data, None))
}

fn check_count(count: u16, max: u16) -> Result<(), u16> {
    if count == 0 || count > max { Err(end_code::POINTS_OUT_OF_RANGE) } else { Ok(()) }
}

/// An error response echoing the serial and route, with error information when the command
/// is known.
pub fn error_response(
    serial: Option<u16>,
    route: frame::Route,
    code: u16,
    command: Option<(u16, u16)>,
) -> Vec<u8> {
    let info = command.map(|(command, subcommand)| ErrorInfo { route, command, subcommand });
    Response { serial, route, outcome: Outcome::Failed { end_code: code, info, trailing: Vec::new() } }
        .encode()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocols::mc3e::frame::Route;
    use crate::protocols::mc3e::scattered;

    fn run(bank: &Mutex<Bank>, command: Command) -> Response {
        let bytes = Request { serial: None, route: Route::default(), monitor_timer: 4, command }.encode();
        Response::decode(&answer(bank, &TypeName::default(), &bytes, None).unwrap().bytes).unwrap()
    }

    fn code(r: &Response) -> u16 {
        match r.outcome {
            Outcome::Failed { end_code, .. } => end_code,
            Outcome::Ok(_) => 0,
        }
    }

    #[test]
    fn reads_writes_and_refusals() {
        let bank = Mutex::new(Bank::with_sizes(&[(Device::D, 2000), (Device::X, 0x40)]));
        let w = run(&bank, Command::WriteWords { device: Device::D, start: 1000, values: vec![0x1234, 2] });
        assert_eq!(w.outcome, Outcome::Ok(vec![]));
        let r = run(&bank, Command::ReadWords { device: Device::D, start: 1000, count: 2 });
        assert_eq!(r.outcome, Outcome::Ok(vec![0x34, 0x12, 0x02, 0x00]));
        assert_eq!(code(&run(&bank, Command::ReadWords { device: Device::D, start: 0, count: 961 })), 0xC051);
        assert_eq!(code(&run(&bank, Command::ReadWords { device: Device::D, start: 0, count: 0 })), 0xC051);
        assert_eq!(
            code(&run(&bank, Command::ReadWords { device: Device::D, start: 1999, count: 2 })),
            0xC056
        );
        assert_eq!(code(&run(&bank, Command::ReadBits { device: Device::X, start: 0x3F, count: 2 })), 0xC056);
        run(&bank, Command::WriteBits { device: Device::X, start: 0x1A, values: vec![true, false, true] });
        let r = run(&bank, Command::ReadBits { device: Device::X, start: 0x19, count: 4 });
        assert_eq!(r.outcome, Outcome::Ok(vec![0x01, 0x01]));
    }

    #[test]
    fn manual_word_unit_examples_answer_byte_for_byte() {
        // MC protocol reference manual (iQ-R SH-081338 8.2 and 8.3, Q/L subcommands; the same
        // examples as SH-080008): M100..M131 read as 2 words answers `34 12 02 00`.
        let bank = Mutex::new(Bank::default());
        bank.lock().unwrap().write_words(Device::M, 100, &[0x1234, 0x0002]).unwrap();
        let r = run(&bank, Command::ReadWords { device: Device::M, start: 100, count: 2 });
        assert_eq!(r.outcome, Outcome::Ok(vec![0x34, 0x12, 0x02, 0x00]));
        // Random read: words D0, T0 (TN), M100..M115, X20..X2F; double words D1500, Y160,
        // M1111, with the manual's stored values.
        {
            let mut b = bank.lock().unwrap();
            b.set_word(Device::D, 0, 0x1995);
            b.set_word(Device::TN, 0, 0x1202);
            b.write_words(Device::M, 100, &[0x2030]).unwrap();
            b.write_words(Device::X, 0x20, &[0x4849]).unwrap();
            b.write_words(Device::D, 1500, &[0x4F4E, 0x4C54]).unwrap();
            b.write_words(Device::Y, 0x160, &[0xB9AF, 0xC3DE]).unwrap();
            b.write_words(Device::M, 1111, &[0xBCB7, 0xBADD]).unwrap();
        }
        let words = vec![(Device::D, 0), (Device::TN, 0), (Device::M, 100), (Device::X, 0x20)];
        let dwords = vec![(Device::D, 1500), (Device::Y, 0x160), (Device::M, 1111)];
        let r = run(&bank, Command::RandomRead { words, dwords });
        let manual = [
            0x95, 0x19, 0x02, 0x12, 0x30, 0x20, 0x49, 0x48, 0x4E, 0x4F, 0x54, 0x4C, 0xAF, 0xB9, 0xDE, 0xC3,
            0xB7, 0xBC, 0xDD, 0xBA,
        ];
        assert_eq!(r.outcome, Outcome::Ok(manual.to_vec()));
    }

    #[test]
    fn scattered_reads_type_name_and_4e() {
        let bank = Mutex::new(Bank::default());
        {
            let mut b = bank.lock().unwrap();
            b.set_word(Device::D, 0, 0x1995);
            b.set_word(Device::TN, 0, 0x1202);
            b.write_words(Device::M, 100, &[0x2030]).unwrap();
            b.write_words(Device::D, 1500, &[0x4849, 0xC34F]).unwrap();
        }
        let words = vec![(Device::D, 0), (Device::TN, 0), (Device::M, 100)];
        let r = run(&bank, Command::RandomRead { words, dwords: vec![(Device::D, 1500)] });
        assert_eq!(r.outcome, Outcome::Ok(vec![0x95, 0x19, 0x02, 0x12, 0x30, 0x20, 0x49, 0x48, 0x4F, 0xC3]));
        let blocks = Command::ReadBlocks {
            words: vec![scattered::Block::new(Device::D, 0, 1)],
            bits: vec![scattered::Block::new(Device::M, 100, 1)],
        };
        assert_eq!(run(&bank, blocks).outcome, Outcome::Ok(vec![0x95, 0x19, 0x30, 0x20]));
        let too_many = Command::RandomRead { words: vec![(Device::D, 0); 193], dwords: vec![] };
        assert_eq!(code(&run(&bank, too_many)), 0xC051);
        let past =
            Command::ReadBlocks { words: vec![scattered::Block::new(Device::D, 12_287, 2)], bits: vec![] };
        assert_eq!(code(&run(&bank, past)), 0xC056);
        let r = run(&bank, Command::ReadTypeName);
        assert_eq!(r.outcome, Outcome::Ok(TypeName::default().encode()));
        // 4E: the reply echoes the serial, errors too.
        let mut request = Request {
            serial: Some(0xBEEF),
            route: Route::default(),
            monitor_timer: 4,
            command: Command::ReadTypeName,
        };
        let reply =
            Response::decode(&answer(&bank, &TypeName::default(), &request.encode(), None).unwrap().bytes)
                .unwrap();
        assert_eq!(reply.serial, Some(0xBEEF));
        request.command = Command::ReadWords { device: Device::D, start: 0, count: 0 };
        let reply =
            Response::decode(&answer(&bank, &TypeName::default(), &request.encode(), None).unwrap().bytes)
                .unwrap();
        assert_eq!((reply.serial, code(&reply)), (Some(0xBEEF), 0xC051));
    }

    #[test]
    fn unknown_command_echoes_error_info() {
        let bank = Mutex::new(Bank::default());
        let mut bytes = Request {
            serial: None,
            route: Route::default(),
            monitor_timer: 4,
            command: Command::ReadWords { device: Device::D, start: 0, count: 1 },
        }
        .encode();
        bytes[11..13].copy_from_slice(&0x0619u16.to_le_bytes());
        let r = Response::decode(&answer(&bank, &TypeName::default(), &bytes, None).unwrap().bytes).unwrap();
        let info = ErrorInfo { route: Route::default(), command: 0x0619, subcommand: 0 };
        assert_eq!(r.outcome, Outcome::Failed { end_code: 0xC059, info: Some(info), trailing: vec![] });
        assert_eq!(answer(&bank, &TypeName::default(), &[0x58, 0x00, 1, 2, 3], None), None);
        let short = [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x00, 0x00];
        let r = Response::decode(&answer(&bank, &TypeName::default(), &short, None).unwrap().bytes).unwrap();
        assert_eq!(r.outcome, Outcome::Failed { end_code: 0xC061, info: None, trailing: vec![] });
    }

    #[test]
    fn forced_end_code_and_write_event() {
        let bank = Mutex::new(Bank::default());
        let bytes = Request {
            serial: None,
            route: Route::default(),
            monitor_timer: 4,
            command: Command::WriteWords { device: Device::D, start: 21, values: vec![1] },
        }
        .encode();
        let a = answer(&bank, &TypeName::default(), &bytes, Some(0xC05F)).unwrap();
        assert_eq!(a.write, None);
        assert_eq!(bank.lock().unwrap().word(Device::D, 21), 0);
        let a = answer(&bank, &TypeName::default(), &bytes, None).unwrap();
        assert_eq!(a.write, Some(WriteEvent { device: Device::D, start: 21, points: 1 }));
        assert_eq!(bank.lock().unwrap().word(Device::D, 21), 1);
    }
}
