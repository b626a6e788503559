//! The simulated crane's text commands (read from stdin by `rackd sim crane`): one line in,
//! what to print out.

use super::inventory::Cell;
use super::{CraneSim, Hold};

/// Why a text command was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// `alarm` with something other than a number.
    #[error("not an alarm code: {0}")]
    AlarmCode(String),
    /// `put`/`take` without four numbers.
    #[error("not a cell (ROW BAY LEVEL SIDE): {0}")]
    Cell(String),
    /// `take` while the crane tracks no inventory.
    #[error("the inventory is not tracked (put a load first, or start with --inventory)")]
    Untracked,
    /// Not one of the commands.
    #[error(
        "unknown command {0:?} (alarm CODE, clear, heartbeat on|off, handshake on|off, hold ack|start|off, force, drop, link on|off, status, put|take ROW BAY LEVEL SIDE, inventory, stats)"
    )]
    Unknown(String),
}

fn cell(words: &[&str]) -> Result<Cell, CommandError> {
    let bad = || CommandError::Cell(words.join(" "));
    let numbers: Vec<u16> = words.iter().map(|w| w.parse().map_err(|_| bad())).collect::<Result<_, _>>()?;
    numbers.try_into().map_err(|_| bad())
}

fn show(c: Cell) -> String {
    format!("{}/{}/{}/{}", c[0], c[1], c[2], c[3])
}

impl CraneSim {
    /// Runs one text command (see the module doc); returns what to print.
    pub fn command(&self, line: &str) -> Result<String, CommandError> {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["alarm", code] => {
                let code: u16 = code.parse().map_err(|_| CommandError::AlarmCode(code.to_string()))?;
                self.raise_alarm(code);
                Ok(format!("alarm {code}: {}", crate::wire::alarms::lookup(code).text))
            }
            ["clear"] => Ok({
                self.clear_alarm();
                "alarm cleared".into()
            }),
            ["heartbeat", on @ ("on" | "off")] => Ok({
                self.set_heartbeat(*on == "on");
                format!("heartbeat {on}")
            }),
            ["handshake", on @ ("on" | "off")] => Ok({
                self.set_handshake(*on == "on");
                format!("handshake {on}")
            }),
            ["hold", at @ ("ack" | "start" | "off")] => Ok({
                self.hold(match *at {
                    "ack" => Some(Hold::BeforeAck),
                    "start" => Some(Hold::BeforeStart),
                    _ => None,
                });
                format!("hold {at}")
            }),
            ["force"] => Ok(if self.force_complete() { "force-completed (30)" } else { "no task" }.into()),
            ["drop"] => Ok({
                self.drop_link();
                "link dropped once".into()
            }),
            ["link", on @ ("on" | "off")] => Ok({
                self.set_link(*on == "on");
                format!("link {on}")
            }),
            ["status"] => Ok(format!(
                "action {} task {} alarm {} load {} travel {} lift {} stb {} ack {} violations {}",
                self.word(203),
                self.word(208),
                self.word(205),
                self.word(206),
                self.word(220),
                self.word(221),
                self.word(21),
                self.word(225),
                self.violations()
            )),
            ["put", rest @ ..] => {
                let c = cell(rest)?;
                Ok(if self.put_load(c) {
                    format!("load put into {}", show(c))
                } else {
                    format!("{} not free", show(c))
                })
            }
            ["take", rest @ ..] => {
                let c = cell(rest)?;
                match self.take_load(c) {
                    None => Err(CommandError::Untracked),
                    Some(true) => Ok(format!("load taken from {}", show(c))),
                    Some(false) => Ok(format!("{} holds no load", show(c))),
                }
            }
            ["inventory"] => Ok(match self.inventory() {
                None => "inventory not tracked".into(),
                Some(cells) => {
                    let list: Vec<String> = cells.into_iter().map(show).collect();
                    format!("{} occupied: {}", list.len(), list.join(" "))
                }
            }),
            ["stats"] => Ok(self.stats().to_string()),
            _ => Err(CommandError::Unknown(line.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::CraneSimOptions;
    use super::*;

    #[tokio::test]
    async fn text_commands_hold_the_hand_over_and_status_counts_violations() {
        let sim = CraneSim::start("127.0.0.1:0", CraneSimOptions::default()).await.unwrap();
        let hold = || sim.engine.lock().unwrap().hold;
        assert_eq!(sim.command("hold ack").unwrap(), "hold ack");
        assert_eq!(hold(), Some(Hold::BeforeAck));
        assert_eq!(sim.command("hold start").unwrap(), "hold start");
        assert_eq!(hold(), Some(Hold::BeforeStart));
        assert_eq!(sim.command("hold off").unwrap(), "hold off");
        assert_eq!(hold(), None);
        assert!(matches!(sim.command("hold later"), Err(CommandError::Unknown(_))));
        let status = sim.command("status").unwrap();
        assert!(status.ends_with("stb 0 ack 0 violations 0"), "{status}");
        sim.shutdown().await;
    }

    #[tokio::test]
    async fn text_commands_load_and_list_the_inventory_and_show_the_stats() {
        let sim = CraneSim::start("127.0.0.1:0", CraneSimOptions::default()).await.unwrap();
        assert_eq!(sim.command("inventory").unwrap(), "inventory not tracked");
        assert_eq!(sim.command("take 1 2 3 1"), Err(CommandError::Untracked));
        assert_eq!(sim.command("put 1 2 3 2").unwrap(), "load put into 1/2/3/2");
        assert_eq!(sim.command("put 1 2 3 2").unwrap(), "1/2/3/2 not free");
        assert_eq!(sim.command("put 2 0 1 1").unwrap(), "2/0/1/1 not free", "a station is no cell");
        sim.command("put 2 5 1 1").unwrap();
        assert_eq!(sim.command("inventory").unwrap(), "2 occupied: 1/2/3/2 2/5/1/1");
        assert_eq!(sim.command("take 2 5 1 1").unwrap(), "load taken from 2/5/1/1");
        assert_eq!(sim.inventory(), Some(vec![[1, 2, 3, 2]]));
        assert!(matches!(sim.command("put 1 2 x 1"), Err(CommandError::Cell(_))));
        assert!(matches!(sim.command("put 1 2 3"), Err(CommandError::Cell(_))));
        sim.command("alarm 7093").unwrap();
        assert!(sim.command("stats").unwrap().ends_with("alarms 7093x1"), "counted by hand too");
        sim.shutdown().await;
    }
}
