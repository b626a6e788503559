//! The shelf PLC's task slot, word by word (spec: shelf-plc.md, "Task slots").
//!
//! A slot is 35 used words: task id, priority, 20 barcode words (one ASCII character per
//! word, from the RIGHT end of the barcode), command, from (5 words), to (5 words),
//! execution state and failure kind. This module only turns jobs into words and words into
//! a [`SlotView`]; it does no I/O.

use crate::domain::{JobSpec, LightColor, Location};
use crate::protocols::Protocol;

/// Words of a slot that rackd writes and reads.
pub const SLOT_WORDS: usize = 35;
/// Offset of the task id word.
pub const TASK_ID: usize = 0;
/// Offset of the first barcode word.
const BARCODE: usize = 2;
/// Offset of the command word.
const COMMAND: usize = 22;
/// Offset of the from position (5 words).
const FROM: usize = 23;
/// Offset of the to position (5 words).
const TO: usize = 28;
/// Offset of the execution state word.
pub const EXEC_STATE: usize = 33;
/// Offset of the failure kind word.
pub const FAILURE_KIND: usize = 34;

/// The PLC's command codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Command {
    /// 1: box onto the shelf.
    Store = 1,
    /// 2: box off the shelf.
    Retrieve = 2,
    /// 3: move a box between positions.
    Move = 3,
    /// 4: clear a position.
    Clear = 4,
    /// 5: green light on.
    GreenOn = 5,
    /// 6: green light off.
    GreenOff = 6,
    /// 7: red light on.
    RedOn = 7,
    /// 8: red light off.
    RedOff = 8,
}

impl Command {
    /// The command for a code word, if it is one.
    pub fn from_code(code: u16) -> Option<Command> {
        use Command::*;
        [Store, Retrieve, Move, Clear, GreenOn, GreenOff, RedOn, RedOff]
            .into_iter()
            .find(|c| *c as u16 == code)
    }
}

/// The execution state word, as the PLC writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExecState {
    /// 0: not started.
    NotStarted,
    /// 1: running.
    Running,
    /// 2: finished.
    Finished,
    /// 3: failed (see the failure kind).
    Failed,
    /// Any other value: a PLC that does not follow the interface.
    Unknown(u16),
}

impl From<u16> for ExecState {
    fn from(w: u16) -> Self {
        match w {
            0 => Self::NotStarted,
            1 => Self::Running,
            2 => Self::Finished,
            3 => Self::Failed,
            other => Self::Unknown(other),
        }
    }
}

/// What a slot holds, as read from the PLC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotView {
    /// The task id; 0 = empty.
    pub task_id: u16,
    /// The execution state.
    pub state: ExecState,
    /// The failure kind: 0 none, 1 PLC fault, 2 command rejected.
    pub failure_kind: u16,
}

impl SlotView {
    /// Reads the view from the slot's first [`SLOT_WORDS`] words (or at least 35).
    pub fn parse(words: &[u16]) -> Option<SlotView> {
        (words.len() >= SLOT_WORDS).then(|| SlotView {
            task_id: words[TASK_ID],
            state: ExecState::from(words[EXEC_STATE]),
            failure_kind: words[FAILURE_KIND],
        })
    }

    /// Rule 1 of the spec: a slot is free if its task id is 0 or its task is finished.
    pub fn is_free(&self) -> bool {
        self.task_id == 0 || self.state == ExecState::Finished
    }
}

/// The command, departure ("from") and end ("to") positions of a job, or why the shelf
/// cannot run it.
///
/// The spec shows only a move and a light; for the other commands rackd reads the two
/// fields literally as departure and end position: a store comes from outside the rack (the
/// HMI counter), so "from" is zero and "to" is the target; a retrieve leaves "to" zero (the
/// box goes out to the counter); a clear names its location in "from"; lights name theirs in
/// "from" with "to" zero, as the seed requires.
pub type Positions = (Command, Option<Location>, Option<Location>);

/// See [`Positions`].
pub fn command_for(spec: &JobSpec) -> Result<Positions, &'static str> {
    Ok(match *spec {
        JobSpec::Store { to } => (Command::Store, None, Some(to)),
        JobSpec::Retrieve { from } => (Command::Retrieve, Some(from), None),
        JobSpec::Move { from, to } => (Command::Move, Some(from), Some(to)),
        JobSpec::Clear { location } => (Command::Clear, Some(location), None),
        JobSpec::Light { location, color, on } => {
            let c = match (color, on) {
                (LightColor::Green, true) => Command::GreenOn,
                (LightColor::Green, false) => Command::GreenOff,
                (LightColor::Red, true) => Command::RedOn,
                (LightColor::Red, false) => Command::RedOff,
            };
            (c, Some(location), None)
        }
        JobSpec::Travel { .. } => return Err("a shelf PLC has no travel command"),
        JobSpec::Putaway { .. } => return Err("a shelf PLC needs the store's location"),
    })
}

/// The words 1..35 of a slot (everything but the task id, which is written last) for a job;
/// see [`command_for`] for what goes into "from" and "to".
pub fn encode_body(
    spec: &JobSpec,
    priority: u8,
    barcode: Option<&str>,
) -> Result<[u16; SLOT_WORDS - 1], &'static str> {
    let (command, from, to) = command_for(spec)?;
    let mut w = [0u16; SLOT_WORDS];
    w[1] = priority as u16;
    for (i, c) in barcode.unwrap_or("").bytes().rev().take(20).enumerate() {
        w[BARCODE + i] = c as u16;
    }
    w[COMMAND] = command as u16;
    if let Some(from) = from {
        put_location(&mut w[FROM..FROM + 5], from);
    }
    if let Some(to) = to {
        put_location(&mut w[TO..TO + 5], to);
    }
    // Execution state and failure kind: the WCS writes 0.
    let mut body = [0u16; SLOT_WORDS - 1];
    body.copy_from_slice(&w[1..]);
    Ok(body)
}

fn put_location(w: &mut [u16], l: Location) {
    w.copy_from_slice(&[l.aisle, l.row, l.bay, l.level, l.position]);
}

/// Reads a location from 5 words; `None` when all are zero.
pub fn location_at(words: &[u16], offset: usize) -> Option<Location> {
    let w = words.get(offset..offset + 5)?;
    (w.iter().any(|&x| x != 0)).then(|| Location {
        aisle: w[0],
        row: w[1],
        bay: w[2],
        level: w[3],
        position: w[4],
    })
}

/// A task as decoded from a full slot (the simulator's view).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Task {
    /// The task id.
    pub id: u16,
    /// Priority, lower first.
    pub priority: u16,
    /// The barcode, restored to reading order.
    pub barcode: String,
    /// The command code word.
    pub command: u16,
    /// From position.
    pub from: Option<Location>,
    /// To position.
    pub to: Option<Location>,
}

impl Task {
    /// Decodes a task from a slot's words.
    pub fn decode(words: &[u16]) -> Option<Task> {
        if words.len() < SLOT_WORDS {
            return None;
        }
        let mut barcode: Vec<u8> =
            words[BARCODE..BARCODE + 20].iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
        barcode.reverse();
        Some(Task {
            id: words[TASK_ID],
            priority: words[1],
            barcode: String::from_utf8_lossy(&barcode).into_owned(),
            command: words[COMMAND],
            from: location_at(words, FROM),
            to: location_at(words, TO),
        })
    }
}

/// Where the task slots sit by default on each protocol: slot 1's task id and the words
/// from one slot to the next. Modbus UDP/TCP: the seed's PLC, `4x4000` (MW4000), 100;
/// Modbus RTU: an S7-1200 Modbus_Slave, whose holding registers start at its slot data
/// block, `4x0`, 100; PPI: an S7-200, `VW1000`, 50 (60 slots of 100 words would not fit its
/// V memory); MEWTOCOL: `DT4000`, 100; MC: `D4000`, 100.
pub fn default_layout(protocol: Protocol) -> (&'static str, u16) {
    match protocol {
        Protocol::ModbusUdp | Protocol::ModbusTcp => ("4x4000", 100),
        Protocol::ModbusRtu | Protocol::ModbusRtuTcp => ("4x0", 100),
        Protocol::Ppi | Protocol::PpiTcp => ("VW1000", 50),
        Protocol::Mewtocol | Protocol::MewtocolTcp => ("DT4000", 100),
        Protocol::Mc3e | Protocol::Mc3eUdp | Protocol::Mc4e | Protocol::Mc4eUdp => ("D4000", 100),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::task_id_for;

    fn loc(aisle: u16, row: u16, bay: u16, level: u16, position: u16) -> Location {
        Location { aisle, row, bay, level, position }
    }

    fn slot(task_id: u16, body: [u16; 34]) -> Vec<u16> {
        let mut w = vec![task_id];
        w.extend_from_slice(&body);
        w
    }

    #[test]
    fn the_seeds_move_example_word_for_word() {
        // Slot 1: move 1-B-2-4-5 to 1-B-2-1-1, priority 2 (shelf-plc.md).
        let spec = JobSpec::Move { from: loc(1, 2, 2, 4, 5), to: loc(1, 2, 2, 1, 1) };
        let w = slot(1, encode_body(&spec, 2, None).unwrap());
        let mut want = vec![0u16; 35];
        want[0] = 1;
        want[1] = 2;
        want[22] = 3;
        want[23..28].copy_from_slice(&[1, 2, 2, 4, 5]);
        want[28..33].copy_from_slice(&[1, 2, 2, 1, 1]);
        assert_eq!(w, want);
    }

    #[test]
    fn the_seeds_light_example_word_for_word() {
        // Slot 2: green light on at 1-B-2-3-5, priority 2, target all zero.
        let spec = JobSpec::Light { location: loc(1, 2, 2, 3, 5), color: LightColor::Green, on: true };
        let w = slot(2, encode_body(&spec, 2, None).unwrap());
        assert_eq!(&w[..2], &[2, 2]);
        assert_eq!(w[22], 5);
        assert_eq!(&w[23..28], &[1, 2, 2, 3, 5]);
        assert_eq!(&w[28..35], &[0; 7]);
    }

    #[test]
    fn barcode_is_written_from_its_right_end() {
        let spec = JobSpec::Store { to: loc(1, 1, 1, 1, 1) };
        let w = slot(7, encode_body(&spec, 10, Some("AB12")).unwrap());
        assert_eq!(&w[2..7], &[b'2' as u16, b'1' as u16, b'B' as u16, b'A' as u16, 0]);
        assert_eq!(Task::decode(&w).unwrap().barcode, "AB12");
        let w = slot(7, encode_body(&spec, 10, Some("ABCDEFGHIJKLMNOPQRST")).unwrap());
        assert_eq!(w[2], b'T' as u16);
        assert_eq!(w[21], b'A' as u16);
    }

    #[test]
    fn commands_for_every_kind() {
        let l = loc(1, 1, 1, 1, 1);
        let cmd = |s: JobSpec| command_for(&s).map(|c| c.0);
        assert_eq!(cmd(JobSpec::Store { to: l }), Ok(Command::Store));
        assert_eq!(cmd(JobSpec::Retrieve { from: l }), Ok(Command::Retrieve));
        assert_eq!(cmd(JobSpec::Clear { location: l }), Ok(Command::Clear));
        assert_eq!(
            cmd(JobSpec::Light { location: l, color: LightColor::Red, on: false }),
            Ok(Command::RedOff)
        );
        assert!(cmd(JobSpec::Travel { to: l }).is_err());
    }

    #[test]
    fn free_slots_follow_rule_one() {
        let mut w = vec![0u16; 35];
        assert!(SlotView::parse(&w).unwrap().is_free());
        w[0] = 9;
        assert!(!SlotView::parse(&w).unwrap().is_free());
        w[33] = 1;
        assert!(!SlotView::parse(&w).unwrap().is_free());
        w[33] = 2;
        assert!(SlotView::parse(&w).unwrap().is_free());
        w[33] = 3;
        assert!(!SlotView::parse(&w).unwrap().is_free(), "a failed task stays until rackd has read it");
        assert!(SlotView::parse(&w[..34]).is_none());
    }

    #[test]
    fn task_ids_are_never_zero() {
        assert_eq!(task_id_for(1), 1);
        assert_eq!(task_id_for(65535), 65535);
        assert_eq!(task_id_for(65536), 1);
    }
}
