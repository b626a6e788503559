//! The engine with a motion model and an inventory, on instants the test advances itself.

use super::*;

const STATION_IN: Cell = [2, 0, 1, 1];
const STATION_OUT: Cell = [1, 0, 1, 1];

/// An engine and its registers on a clock of its own.
struct Rig {
    e: Engine,
    bank: Bank,
    now: Instant,
    task: u16,
}

impl Rig {
    fn new(scale: f64, cells: Option<Vec<Cell>>) -> Rig {
        let mut e = Engine::new(Duration::from_millis(10));
        e.set_motion(Some(Motion::default()));
        e.time_scale = scale;
        e.inventory = cells.map(Inventory::new);
        Rig { e, bank: Bank::default(), now: Instant::now(), task: 0 }
    }

    fn word(&self, n: u32) -> u16 {
        d(&self.bank, n)
    }

    fn tick(&mut self, real: Duration) {
        self.now += real;
        self.e.tick(&mut self.bank, self.now);
    }

    /// Hands over task words (mode, from, to) through STB/ACK.
    fn hand_over(&mut self, mode: u16, from: Cell, to: Cell) {
        self.task += 1;
        let words: Vec<u16> = [self.task, mode].into_iter().chain(from).chain(to).collect();
        for (k, w) in words.iter().enumerate() {
            set(&mut self.bank, 8 + k as u32, *w);
        }
        set(&mut self.bank, 21, 1);
        self.tick(Duration::ZERO);
        assert_eq!(self.word(225), 1, "ACK");
        set(&mut self.bank, 21, 0);
        self.tick(Duration::ZERO);
    }

    /// Ticks every `real` until the task ends (20) or halts on an alarm; returns the ticks.
    fn until_done(&mut self, real: Duration) -> usize {
        for n in 1..100_000 {
            self.tick(real);
            if self.word(203) == 20 || self.word(205) != 0 {
                return n;
            }
        }
        panic!("the task never ended: state {}", self.word(203));
    }

    /// Acknowledges a 20/40 and, after a cancel, waits for homing to end.
    fn acknowledge(&mut self) {
        set(&mut self.bank, 22, 1);
        self.tick(Duration::ZERO);
        set(&mut self.bank, 22, 0);
        while self.word(203) == 100 {
            self.tick(Duration::from_millis(1));
        }
        assert_eq!(self.word(203), 0);
    }

    /// Runs a transfer to its end; returns the alarm it halted on (0: none).
    fn transfer(&mut self, from: Cell, to: Cell) -> u16 {
        self.hand_over(2, from, to);
        self.until_done(Duration::from_millis(5));
        self.word(205)
    }

    fn cancel(&mut self) {
        self.hand_over(3, [0; 4], [0; 4]);
        assert_eq!((self.word(203), self.word(223), self.word(205)), (40, 40, 0));
    }

    fn cells(&self) -> Vec<Cell> {
        self.e.cells().unwrap()
    }
}

#[test]
fn a_transfer_takes_the_models_time_scaled_and_the_axes_follow_it() {
    let m = Motion::default();
    let mut rig = Rig::new(100.0, None);
    let put = [1, 10, 5, 2];
    rig.hand_over(2, STATION_IN, put);
    let expected = m.fork_time(1) + m.move_time(HOME, Spot { bay: 10, level: 5 }) + m.fork_time(2);
    let mut track = Vec::new();
    let mut ms = 0;
    while rig.word(203) != 20 {
        rig.tick(Duration::from_millis(1));
        ms += 1;
        track.push((rig.word(203), rig.word(220), rig.word(221)));
        assert!(ms < 10_000);
    }
    // 100 simulated seconds per real second: done on the first millisecond tick past it.
    let real_ms = expected * 1000.0 / 100.0;
    assert!(ms as f64 >= real_ms && (ms as f64) < real_ms + 1.0, "{ms} ms for {real_ms} ms");
    let travel: Vec<_> = track.iter().filter(|t| matches!(t.0, 11 | 12)).collect();
    assert!(travel.windows(2).all(|w| w[1].1 >= w[0].1 && w[1].2 >= w[0].2), "monotonic");
    let distinct: std::collections::BTreeSet<_> = travel.iter().map(|t| t.1).collect();
    assert!(distinct.len() > 20, "D220 moves continuously: {distinct:?}");
    assert_eq!(track.last().map(|t| (t.1, t.2)), Some((1400, 750)), "10 x 1.4 m, 5 x 1.5 m in cm");
    let stats = &rig.e.stats;
    assert_eq!((stats.cycles, stats.travel_empty_m), (1, 0.0));
    assert!((stats.busy_secs - expected).abs() < 1e-6, "{} s busy", stats.busy_secs);
    let loaded = m.move_time(HOME, Spot { bay: 10, level: 5 });
    assert!((stats.loaded_secs - loaded).abs() < 1e-6, "{stats}");
    assert!((stats.fork_secs - (m.fork_time(1) + m.fork_time(2))).abs() < 1e-6, "{stats}");
    assert_eq!(stats.empty_secs, 0.0, "the crane stood at the station: {stats}");
    assert!((stats.travel_loaded_m - 14.0).abs() < 1e-9 && (stats.lift_m - 6.0).abs() < 1e-9, "{stats}");

    // The crane stands where the task ended: the next pick there needs no travel.
    rig.acknowledge();
    rig.hand_over(2, put, STATION_OUT);
    assert_eq!(rig.word(203), 3, "already at the pick");
    rig.until_done(Duration::from_millis(1));
    assert_eq!((rig.word(220), rig.word(221)), (0, 150));
    let stats = &rig.e.stats;
    assert_eq!(stats.travel_empty_m, 0.0, "no empty travel yet");
    assert!((stats.travel_loaded_m - 28.0).abs() < 1e-9, "{stats}");
    assert!((stats.busy_secs - 2.0 * expected).abs() < 1e-6, "the same way back: {stats}");
}

#[test]
fn each_double_deep_alarm_is_raised_for_its_case_only() {
    for (row, off) in [(1u16, 0u16), (2, 4)] {
        let (near, far) = ([row, 4, 2, 1], [row, 4, 2, 2]);
        let impossible = [
            (vec![near], STATION_IN, near, 7091 + off, 13),
            (vec![near], STATION_IN, far, 7092 + off, 13),
            (vec![far], STATION_IN, far, 7093 + off, 13),
            (vec![near, far], far, STATION_OUT, 7094 + off, 3),
            (vec![], near, STATION_OUT, if row == 1 { 7069 } else { 7070 }, 8),
        ];
        for (cells, from, to, code, state) in impossible {
            let mut rig = Rig::new(1000.0, Some(cells.clone()));
            assert_eq!(rig.transfer(from, to), code, "{cells:?} {from:?} -> {to:?}");
            assert_eq!(rig.word(203), state, "halted where the forks would act");
            assert_eq!(rig.word(206), u16::from(state == 13), "load on the platform");
            rig.tick(Duration::from_secs(1));
            assert_eq!(rig.word(203), state, "the alarm halts the task");
            assert_eq!(rig.e.stats.alarms, [(code, 1)].into(), "{cells:?} {from:?} -> {to:?}");
        }
        let possible = [
            (vec![far], STATION_IN, near),
            (vec![], STATION_IN, far),
            (vec![near, far], near, STATION_OUT),
            (vec![far], far, STATION_OUT),
            (vec![near], near, [row, 9, 1, 2]),
        ];
        for (cells, from, to) in possible {
            let mut rig = Rig::new(1000.0, Some(cells.clone()));
            assert_eq!(rig.transfer(from, to), 0, "{cells:?} {from:?} -> {to:?}");
            assert_eq!(rig.word(203), 20);
            assert!(rig.e.stats.alarms.is_empty());
        }
    }
}

#[test]
fn the_inventory_follows_a_task_and_a_cancel_leaves_it_as_before() {
    let (a, b) = ([1, 3, 1, 1], [2, 4, 2, 1]);
    let mut rig = Rig::new(1000.0, Some(vec![a]));
    assert_eq!(rig.transfer(a, b), 0);
    assert_eq!(rig.cells(), vec![b], "moved from a to b");
    rig.acknowledge();
    assert_eq!(rig.transfer(STATION_IN, a), 0);
    assert_eq!(rig.cells(), vec![a, b], "a station is a source");
    rig.acknowledge();

    // From a to the occupied b: halted at the put with the load on the platform.
    assert_eq!(rig.transfer(a, b), 7095);
    assert_eq!(rig.cells(), vec![b], "a's load is on the platform");
    let halted = rig.e.position();
    rig.cancel();
    assert_eq!(rig.cells(), vec![a, b], "a cancel puts the load back where it was picked");
    assert_eq!(rig.word(206), 0);
    // Homing: from where the cancel caught it back to bay 0, level 1.
    set(&mut rig.bank, 22, 1);
    rig.tick(Duration::ZERO);
    assert_eq!(rig.word(203), 100);
    rig.tick(Duration::from_millis(2));
    let (x, _) = rig.e.position();
    assert!(x < halted.0 && x > 0.0, "on its way home: {x} m");
    rig.acknowledge();
    assert_eq!((rig.word(220), rig.word(221)), (0, 150));
    let stats = &rig.e.stats;
    assert_eq!((stats.cycles, stats.cancelled, stats.alarms.clone()), (2, 1, [(7095, 1)].into()));
    // Empty: home to a (3 bays), b back to the station (4), home from b after the cancel (4);
    // loaded: a to b (1), the station to a (3), a to b again (1).
    assert!((stats.travel_empty_m - 11.0 * 1.4).abs() < 1e-9, "{stats}");
    assert!((stats.travel_loaded_m - 5.0 * 1.4).abs() < 1e-9, "{stats}");

    // Mode 1 travel moves the crane and leaves the inventory alone; the next task starts there.
    rig.hand_over(1, [0; 4], [2, 7, 3, 1]);
    rig.until_done(Duration::from_millis(1));
    assert_eq!((rig.word(220), rig.word(221), rig.cells()), (980, 450, vec![a, b]));
}

#[test]
fn without_an_inventory_every_pick_finds_a_load_and_no_double_deep_alarm_comes() {
    let mut rig = Rig::new(1000.0, None);
    assert_eq!(rig.transfer([1, 4, 2, 2], [2, 4, 2, 2]), 0);
    assert_eq!(rig.word(203), 20);
    assert!(rig.e.cells().is_none() && rig.e.stats.alarms.is_empty());
}

#[test]
fn empty_runs_are_counted_by_the_pair_of_tasks_they_join() {
    use crate::sim::crane::stats::{Pair, Runs, TaskKind};
    let m = Motion::default();
    let mut rig = Rig::new(1000.0, None);
    let (put, pick, from, to) = ([1, 10, 5, 2], [2, 4, 2, 1], [1, 30, 8, 1], [2, 31, 8, 2]);
    for (a, b) in [(STATION_IN, put), (pick, STATION_OUT), (from, to)] {
        assert_eq!(rig.transfer(a, b), 0);
        rig.acknowledge();
    }
    let at = |bay, level| Spot { bay, level };
    let pair = |before, next| Pair { before, next };
    let runs = &rig.e.stats.empty_by_pair;
    assert_eq!(runs.len(), 3, "{runs:?}");
    assert_eq!(runs[&pair(None, TaskKind::Store)], Runs { tasks: 1, secs: 0.0 }, "from the station");
    let after_store = runs[&pair(Some(TaskKind::Store), TaskKind::Retrieve)];
    assert_eq!(after_store.tasks, 1);
    assert!((after_store.secs - m.move_time(at(10, 5), at(4, 2))).abs() < 1e-6, "{after_store:?}");
    let after_retrieve = runs[&pair(Some(TaskKind::Retrieve), TaskKind::Move)];
    assert!((after_retrieve.secs - m.move_time(HOME, at(30, 8))).abs() < 1e-6, "{after_retrieve:?}");
    let sum: f64 = runs.values().map(|r| r.secs).sum();
    assert!((sum - rig.e.stats.empty_secs).abs() < 1e-9, "the pairs share out the empty seconds");
    assert_eq!(pair(Some(TaskKind::Store), TaskKind::Retrieve).to_string(), "store -> retrieve");
    let json = serde_json::to_value(&rig.e.stats).unwrap();
    assert_eq!(json["empty_by_pair"]["first store"]["tasks"], 1, "{json}");
}

#[test]
fn the_timeline_dates_a_completion_to_the_moment_its_time_ran_out() {
    let m = Motion::default();
    let mut rig = Rig::new(100.0, None);
    assert_eq!(rig.transfer(STATION_IN, [1, 10, 5, 2]), 0);
    assert!(rig.e.timeline.is_none(), "not recorded unless asked");
    rig.acknowledge();
    rig.e.timeline = Some(Default::default());
    let start = rig.now;
    rig.hand_over(2, [1, 10, 5, 2], STATION_OUT);
    // Ticks far coarser than the scaled cycle's end would need.
    rig.until_done(Duration::from_millis(7));
    let tasks = rig.e.timeline.as_ref().unwrap().tasks().to_vec();
    assert_eq!(tasks.len(), 1, "{tasks:?}");
    let t = tasks[0];
    assert_eq!((t.number, t.received, t.started), (rig.task, start, Some(start)));
    let (ended, state) = t.ended.unwrap();
    let cycle = m.fork_time(2) + m.move_time(Spot { bay: 10, level: 5 }, HOME) + m.fork_time(1);
    let real = (ended - start).as_secs_f64();
    assert!((real * 100.0 - cycle).abs() < 1e-3, "{real} s real for a {cycle} s cycle at x100");
    assert!(ended < rig.now && state == 20, "before the tick that saw it");
}
