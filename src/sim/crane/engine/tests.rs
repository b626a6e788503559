//! The engine without a motion model: hand-over, fixed steps, watchdog, alarms, cancel.

use super::*;

fn run(e: &mut Engine, bank: &mut Bank, now: &mut Instant, ticks: usize) {
    for _ in 0..ticks {
        *now += Duration::from_millis(10);
        e.tick(bank, *now);
    }
}

#[test]
fn a_transfer_runs_through_the_handshake_to_completion() {
    let mut bank = Bank::default();
    let mut e = Engine::new(Duration::from_millis(10));
    let mut now = Instant::now();
    for (k, w) in [5u16, 2, 2, 0, 1, 1, 1, 3, 2, 1].iter().enumerate() {
        bank.set_word(Device::D, 8 + k as u32, *w);
    }
    bank.set_word(Device::D, 21, 1);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 225), d(&bank, 208)), (1, 5));
    bank.set_word(Device::D, 21, 0);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 225), d(&bank, 203)), (0, 1));
    run(&mut e, &mut bank, &mut now, 20);
    assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 220)), (20, 20, 3000));
    bank.set_word(Device::D, 22, 1);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 208)), (0, 0, 0));
    assert_eq!(e.received[&5], 1);
}

fn strobe(e: &mut Engine, bank: &mut Bank, now: Instant, words: [u16; 10]) {
    for (k, w) in words.iter().enumerate() {
        bank.set_word(Device::D, 8 + k as u32, *w);
    }
    bank.set_word(Device::D, 21, 1);
    e.tick(bank, now);
}

#[test]
fn a_hold_freezes_the_hand_over_at_its_step_and_breaches_are_counted() {
    let mut bank = Bank::default();
    let mut e = Engine::new(Duration::from_millis(10));
    let now = Instant::now();
    e.hold = Some(Hold::BeforeAck);
    strobe(&mut e, &mut bank, now, [5, 1, 0, 0, 0, 0, 1, 3, 1, 1]);
    assert_eq!(d(&bank, 225), 0, "held before step 2");
    e.hold = Some(Hold::BeforeStart);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 225), d(&bank, 208)), (1, 5), "latched");
    bank.set_word(Device::D, 21, 0);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 225), d(&bank, 203)), (1, 0), "held before step 4: not started");
    assert!(e.violations.is_empty(), "{:?}", e.violations);
    // A WCS that hands over another task now breaks the scheme twice over.
    strobe(&mut e, &mut bank, now, [6, 2, 0, 0, 0, 0, 1, 3, 1, 1]);
    assert_eq!(e.violations.len(), 2, "{:?}", e.violations);
    bank.set_word(Device::D, 15, 9);
    e.tick(&mut bank, now);
    assert_eq!(e.violations.len(), 3, "words changed under the strobe: {:?}", e.violations);
    bank.set_word(Device::D, 21, 0);
    e.hold = None;
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 225), d(&bank, 203)), (0, 1), "released: starts the task it latched");
    assert_eq!(e.received.get(&6), None, "the second task was never taken");
}

#[test]
fn the_watchdog_raises_7020_when_the_wcs_stalls_and_clears_it_when_it_moves() {
    let mut bank = Bank::default();
    let mut e = Engine::new(Duration::from_millis(10));
    e.wcs_timeout = Some(Duration::from_millis(100));
    let mut now = Instant::now();
    run(&mut e, &mut bank, &mut now, 5);
    assert_eq!(d(&bank, 205), 0);
    run(&mut e, &mut bank, &mut now, 10);
    assert_eq!(d(&bank, 205), HEARTBEAT_ALARM);
    bank.set_word(Device::D, 0, 1);
    run(&mut e, &mut bank, &mut now, 1);
    assert_eq!(d(&bank, 205), 0);
}

#[test]
fn an_alarm_halts_and_a_cancel_ends_in_40() {
    let mut bank = Bank::default();
    let mut e = Engine::new(Duration::from_millis(10));
    let mut now = Instant::now();
    bank.set_word(Device::D, 8, 9);
    bank.set_word(Device::D, 9, 2);
    bank.set_word(Device::D, 21, 1);
    e.tick(&mut bank, now);
    bank.set_word(Device::D, 21, 0);
    e.tick(&mut bank, now);
    run(&mut e, &mut bank, &mut now, 3);
    bank.set_word(Device::D, 205, 7069);
    let halted = d(&bank, 203);
    run(&mut e, &mut bank, &mut now, 5);
    assert_eq!(d(&bank, 203), halted);
    bank.set_word(Device::D, 9, 3);
    bank.set_word(Device::D, 21, 1);
    e.tick(&mut bank, now);
    bank.set_word(Device::D, 21, 0);
    e.tick(&mut bank, now);
    assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 205)), (40, 40, 0));
    bank.set_word(Device::D, 22, 1);
    e.tick(&mut bank, now);
    assert_eq!(d(&bank, 203), 100);
    run(&mut e, &mut bank, &mut now, 2);
    assert_eq!(d(&bank, 203), 0);
}
