//! What the machines' interfaces look like on the wire, word by word: the shelf PLC's task
//! slot ([`slot`]), the stacker crane's register map ([`registers`]), its alarm catalogue
//! ([`alarms`]), how it moves ([`motion`]), and a site's tags ([`tags`]: named, typed
//! addresses and how their values sit in words).
//!
//! No I/O, and nothing of rackd's but the [`crate::domain`] words and the protocols' names
//! and notations ([`crate::protocols`], which parse an address without a connection). The
//! device adapters (which drive real machines), the configuration (which checks them) and
//! the simulators (which play them) all read the interface from here, so none depends on
//! another.

pub mod alarms;
pub mod motion;
pub mod registers;
pub mod slot;
pub mod tags;

/// The task number rackd gives a job on a machine (a shelf slot's task id, a crane's task
/// number): derived from the job id (1..=65535, never 0), so after a restart the number a
/// machine shows leads back to its job without any extra record.
pub fn task_id_for(job_id: i64) -> u16 {
    ((job_id - 1).rem_euclid(65535) + 1) as u16
}
