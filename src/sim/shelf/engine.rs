//! The shelf machine: one task at a time, lowest priority number first (then slot order),
//! each through execution state 0 → 1 → 2 (or 3 with a failure kind) in the configured
//! time. It works on [`SlotMemory`], so it runs the same behind every transport.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::Rng;

use super::slots::{Core, SlotMemory};
use crate::wire::slot::{EXEC_STATE, FAILURE_KIND, SLOT_WORDS, TASK_ID, Task};

/// How the machine works.
#[derive(Clone, Copy, Debug)]
pub(super) struct Machine {
    /// Time each task takes.
    pub task_time: Duration,
    /// Fraction of tasks failing with kind 1 (PLC fault).
    pub fail_rate: f64,
}

/// Runs the machine until the task is aborted; how it works is read for each task, so it
/// can be changed while it runs ([`super::ShelfSim::set_task_time`]).
pub(super) async fn run(memory: Arc<dyn SlotMemory>, core: Core, machine: Arc<Mutex<Machine>>) {
    loop {
        let machine = *machine.lock().unwrap_or_else(|p| p.into_inner());
        let Some(slot) = start_next(memory.as_ref(), &core) else {
            // Writes ring the bell; the timeout also catches slots changed behind the
            // server's back (tests setting words directly).
            let _ = tokio::time::timeout(Duration::from_millis(50), core.wake.notified()).await;
            continue;
        };
        if !machine.task_time.is_zero() {
            tokio::time::sleep(machine.task_time).await;
        }
        finish(memory.as_ref(), &core, slot, machine.fail_rate);
    }
}

/// Takes the waiting task with the lowest priority number (then the lowest slot) and sets
/// it running; its slot (0-based), if any.
fn start_next(memory: &dyn SlotMemory, core: &Core) -> Option<u16> {
    let layout = core.layout;
    let mut words = memory.lock();
    let next = (0..layout.slots)
        .filter_map(|k| {
            let start = layout.start(k);
            let (id, state) = (words.get(start + TASK_ID), words.get(start + EXEC_STATE));
            (id != 0 && state == 0).then(|| (words.get(start + 1), k))
        })
        .min();
    let (_, slot) = next?;
    words.set(layout.start(slot) + EXEC_STATE, 1);
    Some(slot)
}

/// Ends the running task of `slot`: performs it on the shelf, or fails it with kind 1 (at
/// the fail rate) or kind 2 (the PLC's data disagrees).
fn finish(memory: &dyn SlotMemory, core: &Core, slot: u16, fail_rate: f64) {
    let start = core.layout.start(slot);
    let mut words = memory.lock();
    let Some(task) = Task::decode(&words.read(start, SLOT_WORDS)) else { return };
    if task.id == 0 || words.get(start + EXEC_STATE) != 1 {
        return; // withdrawn or overwritten while running (a violation, already counted)
    }
    let mut world = core.world();
    let outcome = if rand::rng().random_bool(fail_rate.clamp(0.0, 1.0)) {
        Err(1)
    } else {
        world.perform(&task).map_err(|_| 2)
    };
    match outcome {
        Ok(()) => {
            words.set(start + EXEC_STATE, 2);
            world.completed += 1;
        }
        Err(kind) => {
            words.set(start + FAILURE_KIND, kind);
            words.set(start + EXEC_STATE, 3);
            world.failed += 1;
            tracing::info!(slot = slot + 1, task = task.id, kind, "task failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;
    use crate::domain::{JobSpec, Location};
    use crate::sim::shelf::slots::{Layout, VecMemory};
    use crate::wire::slot::encode_body;

    fn put(memory: &VecMemory, slot: usize, id: u16, spec: &JobSpec, priority: u8) {
        let body = encode_body(spec, priority, Some("BX")).unwrap();
        let mut w = memory.0.lock().unwrap();
        w[slot * 100 + 1..slot * 100 + SLOT_WORDS].copy_from_slice(&body);
        w[slot * 100] = id;
    }

    fn state(memory: &VecMemory, slot: usize) -> (u16, u16) {
        let w = memory.0.lock().unwrap();
        (w[slot * 100 + EXEC_STATE], w[slot * 100 + FAILURE_KIND])
    }

    #[test]
    fn runs_the_most_urgent_task_first_and_rejects_what_disagrees() {
        let memory = VecMemory(Mutex::new(vec![0; 300]));
        let core = Core::new(Layout { slots: 3, stride: 100 });
        let to = Location { aisle: 1, row: 1, bay: 1, level: 1, position: 1 };
        put(&memory, 0, 10, &JobSpec::Retrieve { from: to }, 5);
        put(&memory, 2, 12, &JobSpec::Store { to }, 1);
        assert_eq!(start_next(&memory, &core), Some(2), "priority 1 before 5");
        assert_eq!(state(&memory, 2), (1, 0));
        finish(&memory, &core, 2, 0.0);
        assert_eq!(state(&memory, 2), (2, 0));
        assert_eq!(core.world().inventory.get(&to).map(String::as_str), Some("BX"));
        put(&memory, 1, 11, &JobSpec::Retrieve { from: to }, 5);
        assert_eq!(start_next(&memory, &core), Some(0), "same priority: lower slot first");
        finish(&memory, &core, 0, 0.0);
        assert_eq!(state(&memory, 0), (2, 0));
        assert_eq!(start_next(&memory, &core), Some(1));
        finish(&memory, &core, 1, 0.0);
        assert_eq!(state(&memory, 1), (3, 2), "the place is empty again: rejected");
        assert_eq!(start_next(&memory, &core), None);
        let world = core.world();
        assert_eq!((world.completed, world.failed), (2, 1));
    }

    #[test]
    fn fails_with_kind_one_at_the_fail_rate_and_skips_withdrawn_tasks() {
        let memory = VecMemory(Mutex::new(vec![0; 200]));
        let core = Core::new(Layout { slots: 2, stride: 100 });
        let to = Location { aisle: 1, row: 2, bay: 3, level: 4, position: 1 };
        put(&memory, 0, 3, &JobSpec::Store { to }, 1);
        assert_eq!(start_next(&memory, &core), Some(0));
        finish(&memory, &core, 0, 1.0);
        assert_eq!(state(&memory, 0), (3, 1));
        assert!(core.world().inventory.is_empty());
        put(&memory, 1, 4, &JobSpec::Store { to }, 1);
        assert_eq!(start_next(&memory, &core), Some(1));
        memory.0.lock().unwrap()[100] = 0;
        finish(&memory, &core, 1, 0.0);
        assert_eq!(state(&memory, 1), (1, 0), "a cleared slot is left alone");
    }

    #[tokio::test]
    async fn the_running_machine_finishes_tasks_after_the_task_time() {
        let memory = Arc::new(VecMemory(Mutex::new(vec![0; 100])));
        let core = Core::new(Layout { slots: 1, stride: 100 });
        let machine = Machine { task_time: Duration::from_millis(30), fail_rate: 0.0 };
        let engine = tokio::spawn(run(memory.clone(), core.clone(), Arc::new(Mutex::new(machine))));
        let at = Location { aisle: 1, row: 1, bay: 2, level: 1, position: 1 };
        put(
            &memory,
            0,
            1,
            &JobSpec::Light { location: at, color: crate::domain::LightColor::Red, on: true },
            1,
        );
        core.wake.notify_one();
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        while state(&memory, 0).0 != 2 {
            assert!(std::time::Instant::now() < deadline, "the task never finished");
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        assert_eq!(core.world().lights.get(&(at, "red")), Some(&true));
        engine.abort();
    }
}
