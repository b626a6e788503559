//! MEWTOCOL-COM commands (the frame body after `#`) and responses (after `$`), as values.
//!
//! Supported: RCS, RCP, RCC, WCS, WCP, WCC (contacts X, Y, R, L, T, C) and RD, WD (data
//! registers DT). Word data travels as 4 hex characters per word, low byte first.

use super::contact::decimal;
pub use super::contact::{
    Contact, ContactArea, MAX_CONTACT_WORD, MAX_CONTACTS, MAX_DT, MAX_WORD, parse_words, push_word,
};
use super::error_code::{FORMAT_ERROR, NOT_SUPPORTED, PARAMETER_ERROR};

/// A command from the computer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// RCS: read one contact.
    ReadContact(Contact),
    /// RCP: read 1..=8 contacts.
    ReadContacts(Vec<Contact>),
    /// RCC: read contact words `start..=end` of an area.
    ReadContactWords {
        /// The area.
        area: ContactArea,
        /// First word.
        start: u16,
        /// Last word (inclusive).
        end: u16,
    },
    /// WCS: write one contact.
    WriteContact(Contact, bool),
    /// WCP: write 1..=8 contacts.
    WriteContacts(Vec<(Contact, bool)>),
    /// WCC: write contact words from `start`.
    WriteContactWords {
        /// The area.
        area: ContactArea,
        /// First word.
        start: u16,
        /// The words.
        values: Vec<u16>,
    },
    /// RD: read data registers DT `start..=end`.
    ReadData {
        /// First register.
        start: u32,
        /// Last register (inclusive).
        end: u32,
    },
    /// WD: write data registers from DT `start`.
    WriteData {
        /// First register.
        start: u32,
        /// The words.
        values: Vec<u16>,
    },
}

/// A normal response's content.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Response {
    /// RCS: the contact's state.
    Contact(bool),
    /// RCP: the contacts' states.
    Contacts(Vec<bool>),
    /// RCC or RD: the words.
    Words(Vec<u16>),
    /// WCS, WCP, WCC or WD: done.
    Written,
}

impl Request {
    /// Whether the command changes the PLC's memory (a write), rather than reads it.
    pub fn is_write(&self) -> bool {
        matches!(
            self,
            Request::WriteContact(..)
                | Request::WriteContacts(_)
                | Request::WriteContactWords { .. }
                | Request::WriteData { .. }
        )
    }

    /// The two letters of a normal response to this command.
    pub fn reply_code(&self) -> &'static [u8; 2] {
        match self {
            Request::ReadContact(_) | Request::ReadContacts(_) | Request::ReadContactWords { .. } => b"RC",
            Request::WriteContact(..) | Request::WriteContacts(_) | Request::WriteContactWords { .. } => {
                b"WC"
            }
            Request::ReadData { .. } => b"RD",
            Request::WriteData { .. } => b"WD",
        }
    }

    /// Checks counts and ranges before sending.
    pub fn check(&self) -> Result<(), &'static str> {
        let contact_ok = |c: &Contact| c.word <= MAX_CONTACT_WORD && c.bit < 16;
        let ok = match self {
            Request::ReadContact(c) | Request::WriteContact(c, _) => contact_ok(c),
            Request::ReadContacts(cs) => (1..=MAX_CONTACTS).contains(&cs.len()) && cs.iter().all(contact_ok),
            Request::WriteContacts(cs) => {
                (1..=MAX_CONTACTS).contains(&cs.len()) && cs.iter().all(|(c, _)| contact_ok(c))
            }
            Request::ReadContactWords { start, end, .. } => start <= end && *end <= MAX_WORD,
            Request::WriteContactWords { start, values, .. } => {
                !values.is_empty() && *start as usize + values.len() - 1 <= MAX_WORD as usize
            }
            Request::ReadData { start, end } => start <= end && *end <= MAX_DT,
            Request::WriteData { start, values } => {
                !values.is_empty() && *start as u64 + values.len() as u64 - 1 <= MAX_DT as u64
            }
        };
        if ok { Ok(()) } else { Err("MEWTOCOL address or count out of range") }
    }

    /// Appends the command body (what follows `#`).
    pub fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Request::ReadContact(c) => {
                out.extend_from_slice(b"RCS");
                c.encode(out);
            }
            Request::ReadContacts(cs) => {
                out.extend_from_slice(format!("RCP{}", cs.len()).as_bytes());
                cs.iter().for_each(|c| c.encode(out));
            }
            Request::ReadContactWords { area, start, end } => {
                out.extend_from_slice(b"RCC");
                out.push(area.letter());
                out.extend_from_slice(format!("{start:04}{end:04}").as_bytes());
            }
            Request::WriteContact(c, v) => {
                out.extend_from_slice(b"WCS");
                c.encode(out);
                out.push(if *v { b'1' } else { b'0' });
            }
            Request::WriteContacts(cs) => {
                out.extend_from_slice(format!("WCP{}", cs.len()).as_bytes());
                for (c, v) in cs {
                    c.encode(out);
                    out.push(if *v { b'1' } else { b'0' });
                }
            }
            Request::WriteContactWords { area, start, values } => {
                out.extend_from_slice(b"WCC");
                out.push(area.letter());
                let end = *start as usize + values.len().max(1) - 1;
                out.extend_from_slice(format!("{start:04}{end:04}").as_bytes());
                values.iter().for_each(|&w| push_word(out, w));
            }
            Request::ReadData { start, end } => {
                out.extend_from_slice(format!("RDD{start:05}{end:05}").as_bytes());
            }
            Request::WriteData { start, values } => {
                let end = *start as usize + values.len().max(1) - 1;
                out.extend_from_slice(format!("WDD{start:05}{end:05}").as_bytes());
                values.iter().for_each(|&w| push_word(out, w));
            }
        }
    }

    /// Decodes a command body (server side); the error is the MEWTOCOL code to answer.
    pub fn decode(body: &[u8]) -> Result<Request, u8> {
        let fmt = FORMAT_ERROR;
        let Some(name) = body.get(..3) else { return Err(NOT_SUPPORTED) };
        let rest = &body[3..];
        let flag = |c: u8| match c {
            b'0' => Ok(false),
            b'1' => Ok(true),
            _ => Err(fmt),
        };
        let request = match name {
            b"RCS" if rest.len() == 5 => Request::ReadContact(Contact::decode(rest).ok_or(fmt)?),
            b"WCS" if rest.len() == 6 => {
                Request::WriteContact(Contact::decode(rest).ok_or(fmt)?, flag(rest[5])?)
            }
            b"RCP" | b"WCP" => {
                let n = decimal(rest.get(..1).ok_or(fmt)?).ok_or(fmt)? as usize;
                if !(1..=MAX_CONTACTS).contains(&n) {
                    return Err(PARAMETER_ERROR);
                }
                let item = if name == b"RCP" { 5 } else { 6 };
                if rest.len() != 1 + n * item {
                    return Err(fmt);
                }
                let items = rest[1..].chunks(item);
                if name == b"RCP" {
                    Request::ReadContacts(
                        items.map(|c| Contact::decode(c).ok_or(fmt)).collect::<Result<_, _>>()?,
                    )
                } else {
                    Request::WriteContacts(
                        items
                            .map(|c| Ok((Contact::decode(c).ok_or(fmt)?, flag(c[5])?)))
                            .collect::<Result<_, u8>>()?,
                    )
                }
            }
            b"RCC" | b"WCC" if rest.len() >= 9 => {
                let area = ContactArea::from_letter(rest[0]).ok_or(fmt)?;
                let start = decimal(&rest[1..5]).ok_or(fmt)? as u16;
                let end = decimal(&rest[5..9]).ok_or(fmt)? as u16;
                if end < start {
                    return Err(PARAMETER_ERROR);
                }
                if name == b"RCC" {
                    if rest.len() != 9 {
                        return Err(fmt);
                    }
                    Request::ReadContactWords { area, start, end }
                } else {
                    let values = parse_words(&rest[9..]).ok_or(fmt)?;
                    if values.len() != (end - start + 1) as usize {
                        return Err(fmt);
                    }
                    Request::WriteContactWords { area, start, values }
                }
            }
            b"RDD" | b"WDD" if rest.len() >= 10 => {
                let start = decimal(&rest[..5]).ok_or(fmt)?;
                let end = decimal(&rest[5..10]).ok_or(fmt)?;
                if end < start {
                    return Err(PARAMETER_ERROR);
                }
                if name == b"RDD" {
                    if rest.len() != 10 {
                        return Err(fmt);
                    }
                    Request::ReadData { start, end }
                } else {
                    let values = parse_words(&rest[10..]).ok_or(fmt)?;
                    if values.len() as u32 != end - start + 1 {
                        return Err(fmt);
                    }
                    Request::WriteData { start, values }
                }
            }
            b"RCS" | b"WCS" | b"RCC" | b"WCC" | b"RDD" | b"WDD" => return Err(fmt),
            _ => return Err(NOT_SUPPORTED),
        };
        Ok(request)
    }

    /// Decodes the body of a normal response to this command (client side).
    pub fn decode_response(&self, body: &[u8]) -> Result<Response, &'static str> {
        if body.get(..2) != Some(&self.reply_code()[..]) {
            return Err("response code differs from the command");
        }
        let data = &body[2..];
        let bit = |c: &u8| match c {
            b'0' => Ok(false),
            b'1' => Ok(true),
            _ => Err("contact state is not 0 or 1"),
        };
        match self {
            Request::ReadContact(_) => match data {
                [c] => bit(c).map(Response::Contact),
                _ => Err("RCS response is not one contact"),
            },
            Request::ReadContacts(cs) if data.len() == cs.len() => {
                data.iter().map(bit).collect::<Result<_, _>>().map(Response::Contacts)
            }
            Request::ReadContacts(_) => Err("RCP response has the wrong number of contacts"),
            Request::ReadContactWords { start, end, .. } => {
                words(data, end.saturating_sub(*start) as usize + 1)
            }
            Request::ReadData { start, end } => words(data, end.saturating_sub(*start) as usize + 1),
            _ if data.is_empty() => Ok(Response::Written),
            _ => Err("write response carries data"),
        }
    }
}

fn words(data: &[u8], count: usize) -> Result<Response, &'static str> {
    match parse_words(data) {
        Some(w) if w.len() == count => Ok(Response::Words(w)),
        Some(_) => Err("response has the wrong number of words"),
        None => Err("word data is not hex"),
    }
}

impl Response {
    /// Appends a normal response body (code + data) answering `request`.
    pub fn encode(&self, request: &Request, out: &mut Vec<u8>) {
        out.extend_from_slice(request.reply_code());
        match self {
            Response::Contact(v) => out.push(if *v { b'1' } else { b'0' }),
            Response::Contacts(vs) => out.extend(vs.iter().map(|&v| if v { b'1' } else { b'0' })),
            Response::Words(ws) => ws.iter().for_each(|&w| push_word(out, w)),
            Response::Written => {}
        }
    }
}

#[cfg(test)]
#[path = "command_tests.rs"]
mod tests;
