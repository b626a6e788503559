//! The task-slot area as every transport sees it: words counted from slot 1's task id, in
//! whichever bank the protocol serves ([`SlotMemory`]), and the rule-1 watch that looks at
//! each write before it is applied ([`Core::check`], then [`Core::commit`] once it was).
//!
//! Each transport adapter turns its own write requests into `(area word, value)` pairs and
//! calls the watch with its bank locked; locks are always taken bank first, then world.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::Notify;

use super::world::World;
use crate::wire::slot::{EXEC_STATE, SLOT_WORDS, TASK_ID};

/// How the slots lie in the area: `slots` of them, `stride` words apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Layout {
    /// Number of slots.
    pub slots: u16,
    /// Words from one slot to the next (at least [`SLOT_WORDS`]).
    pub stride: u16,
}

impl Layout {
    /// Words the area spans, the last slot's unused tail included.
    pub fn words(&self) -> usize {
        self.slots as usize * self.stride as usize
    }

    /// The area word of slot `slot`'s (0-based) task id.
    pub fn start(&self, slot: u16) -> usize {
        slot as usize * self.stride as usize
    }

    /// The slot (0-based) and offset of an area word, if it is one of a slot's used words.
    fn slot_of(&self, n: usize) -> Option<(u16, usize)> {
        let (slot, offset) = (n / self.stride as usize, n % self.stride as usize);
        (slot < self.slots as usize && offset < SLOT_WORDS).then_some((slot as u16, offset))
    }
}

/// The slot area's words in a locked bank, counted from slot 1's task id.
pub(super) trait SlotWords {
    /// Word `n` of the area (0 past the bank's end).
    fn get(&self, n: usize) -> u16;

    /// Sets word `n` of the area (ignored past the bank's end).
    fn set(&mut self, n: usize, value: u16);

    /// Words `n .. n + len`.
    fn read(&self, n: usize, len: usize) -> Vec<u16> {
        (n..n + len).map(|i| self.get(i)).collect()
    }
}

/// A protocol's bank, seen as the slot area: Modbus holding registers, PPI V memory (two
/// bytes a word, big-endian), MEWTOCOL DT registers.
pub(super) trait SlotMemory: Send + Sync + 'static {
    /// Locks the bank; keep the guard short, the server waits on it.
    fn lock(&self) -> Box<dyn SlotWords + '_>;
}

/// What the transports and the engine share: the layout, the world and the engine's bell.
#[derive(Clone)]
pub(super) struct Core {
    /// Where the slots are.
    pub layout: Layout,
    /// The shelf and the counters.
    pub world: Arc<Mutex<World>>,
    /// Rung after each write into the area, so the engine looks at once.
    pub wake: Arc<Notify>,
}

/// What one write into the slot area means under rule 1, worked out before it is applied.
#[derive(Debug, Default, PartialEq, Eq)]
pub(super) struct Check {
    touched: bool,
    events: Vec<Event>,
}

#[derive(Debug, PartialEq, Eq)]
enum Event {
    /// A write into a busy slot (task id set, not finished).
    Violation { slot: u16, task: u16, state: u16 },
    /// Task id := 0 on a task not yet started.
    Withdrawal,
    /// A new task id reached a slot.
    Received { slot: u16, task: u16 },
}

impl Core {
    /// A core for `layout` with an empty shelf.
    pub fn new(layout: Layout) -> Self {
        Core { layout, world: Arc::default(), wake: Arc::default() }
    }

    /// The world, locked (a panic elsewhere leaves plain data: keep using it).
    pub fn world(&self) -> MutexGuard<'_, World> {
        self.world.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Looks at a write of `(area word, value)` pairs before it is applied; `read` gives the
    /// area's words as they are. The one write into a busy slot that is allowed is task id
    /// := 0 on a task not yet running (a withdraw) or on a failed one (acknowledging it).
    ///
    /// A write that changes no word of a busy slot is not counted: it overwrites nothing,
    /// and it is what a transport retry looks like when the PLC carried out the first
    /// attempt but its reply was lost (PPI executes a request before the master polls for
    /// the response, so a lost response means the retried write arrives twice).
    pub fn check(&self, read: &dyn Fn(usize) -> u16, writes: &[(usize, u16)]) -> Check {
        let mut touched: BTreeMap<u16, Vec<(usize, u16)>> = BTreeMap::new();
        for &(n, v) in writes {
            if let Some((slot, offset)) = self.layout.slot_of(n) {
                touched.entry(slot).or_default().push((offset, v));
            }
        }
        let mut check = Check { touched: !touched.is_empty(), events: Vec::new() };
        for (slot, writes) in touched {
            let start = self.layout.start(slot);
            let (id, state) = (read(start + TASK_ID), read(start + EXEC_STATE));
            let only_clears_id = writes.iter().all(|&(o, v)| o == TASK_ID && v == 0);
            let changes = writes.iter().any(|&(o, v)| read(start + o) != v);
            if id != 0 && state != 2 && changes {
                match (only_clears_id, state) {
                    (true, 0) => check.events.push(Event::Withdrawal),
                    (true, 3) => {}
                    _ => check.events.push(Event::Violation { slot, task: id, state }),
                }
            }
            let new_id = writes.iter().rev().find(|&&(o, _)| o == TASK_ID).map(|&(_, v)| v);
            if let Some(task) = new_id.filter(|&v| v != 0 && v != id) {
                check.events.push(Event::Received { slot, task });
            }
        }
        check
    }

    /// Records a checked write once the bank has applied it, and wakes the engine.
    pub fn commit(&self, check: Check) {
        if !check.touched {
            return;
        }
        let mut world = self.world();
        for event in check.events {
            match event {
                Event::Violation { slot, task, state } => {
                    world.violations += 1;
                    tracing::warn!(slot = slot + 1, task, state, "VIOLATION: write into a busy slot");
                }
                Event::Withdrawal => world.withdrawals += 1,
                Event::Received { slot, task } => {
                    *world.received.entry(task).or_default() += 1;
                    world.received_at.insert(task, std::time::Instant::now());
                    tracing::info!(slot = slot + 1, task, "task received");
                }
            }
        }
        drop(world);
        self.wake.notify_one();
    }
}

/// A plain vector as slot memory, for tests of the engine and the watch.
#[cfg(test)]
pub(super) struct VecMemory(pub Mutex<Vec<u16>>);

#[cfg(test)]
impl SlotWords for MutexGuard<'_, Vec<u16>> {
    fn get(&self, n: usize) -> u16 {
        self.as_slice().get(n).copied().unwrap_or(0)
    }

    fn set(&mut self, n: usize, value: u16) {
        if let Some(w) = self.get_mut(n) {
            *w = value;
        }
    }
}

#[cfg(test)]
impl SlotMemory for VecMemory {
    fn lock(&self) -> Box<dyn SlotWords + '_> {
        Box::new(self.0.lock().unwrap_or_else(|p| p.into_inner()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn core() -> Core {
        Core::new(Layout { slots: 3, stride: 100 })
    }

    /// Slot words with slot 2 (0-based 1) holding task 7 in `state`.
    fn area(state: u16) -> Vec<u16> {
        let mut w = vec![0; 300];
        w[100] = 7;
        w[100 + EXEC_STATE] = state;
        w
    }

    fn run(core: &Core, area: &[u16], writes: &[(usize, u16)]) {
        let check = core.check(&|n| area[n], writes);
        core.commit(check);
    }

    #[test]
    fn layout_maps_words_to_used_slot_words_only() {
        let l = Layout { slots: 2, stride: 100 };
        assert_eq!(l.slot_of(0), Some((0, 0)));
        assert_eq!(l.slot_of(134), Some((1, 34)));
        assert_eq!(l.slot_of(35), None, "reserved words");
        assert_eq!(l.slot_of(200), None, "past the last slot");
        assert_eq!((l.words(), l.start(1)), (200, 100));
    }

    #[test]
    fn writes_into_busy_slots_are_violations_and_new_ids_are_counted() {
        let core = core();
        run(&core, &area(1), &[(101, 5)]);
        assert_eq!(core.world().violations, 1, "body write into a running slot");
        run(&core, &area(1), &[(100, 0)]);
        assert_eq!(core.world().violations, 2, "clearing a running task is no withdraw");
        run(&core, &area(0), &[(100, 0)]);
        let world = core.world();
        assert_eq!((world.violations, world.withdrawals), (2, 1));
        drop(world);
        run(&core, &area(3), &[(100, 0)]);
        assert_eq!(core.world().violations, 2, "acknowledging a failure is allowed");
        run(&core, &area(1), &[(100, 7), (101, 0)]);
        assert_eq!(core.world().violations, 2, "a repeated write that changes nothing overwrites nothing");
        run(&core, &area(1), &[(100, 7), (101, 1)]);
        assert_eq!(core.world().violations, 3, "one changed word is enough");
        run(&core, &area(2), &[(101, 1), (102, 2)]);
        run(&core, &area(2), &[(100, 9)]);
        assert_eq!(core.world().violations, 3, "a finished slot is free");
        assert_eq!(core.world().received.get(&9), Some(&1));
        run(&core, &area(0), &[(35, 1), (300, 4), (5, 1), (0, 8)]);
        assert_eq!(core.world().received.get(&8), Some(&1), "free slot 1 takes task 8");
        assert_eq!(core.world().violations, 3, "reserved words and words past the area are not watched");
    }

    #[tokio::test]
    async fn only_writes_into_the_area_ring_the_engine() {
        let core = core();
        run(&core, &area(0), &[(36, 1)]);
        let rung = tokio::time::timeout(std::time::Duration::from_millis(20), core.wake.notified()).await;
        assert!(rung.is_err(), "a reserved word is no news");
        run(&core, &area(0), &[(200, 1)]);
        core.wake.notified().await;
    }
}
