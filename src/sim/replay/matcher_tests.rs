use super::*;

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

/// Where a write's data begins in these keys: after its `=` ("D0=1": place "D0=", data 1).
fn data_at(key: &str, read: bool) -> Option<usize> {
    key.find('=').filter(|_| !read).map(|i| i + 1)
}

/// A recorded request at `at` ms: `key` names it, `read` says what it is; its reply is
/// `answer` (kept in the reply's bytes, to tell which occurrence was taken).
fn req(at: u64, key: &str, read: bool, answer: &str) -> Recorded {
    Recorded {
        at: ms(at),
        bytes: key.as_bytes().to_vec(),
        key: key.as_bytes().to_vec(),
        read,
        data_at: data_at(key, read),
        replies: vec![super::super::script::Reply { after: ms(1), bytes: answer.as_bytes().to_vec() }],
    }
}

fn read(at: u64, key: &str, answer: &str) -> Recorded {
    req(at, key, true, answer)
}

fn write(at: u64, key: &str) -> Recorded {
    req(at, key, false, "ok")
}

/// The answer a live request gets, and how it was taken.
fn ask(m: &mut Matcher, key: &str, is_read: bool, now: u64) -> (String, Taken) {
    let request = Request { key: key.as_bytes(), read: is_read, data_at: data_at(key, is_read) };
    let (i, taken) = m.take(request, ms(now));
    let answer =
        i.map_or("-".into(), |i| String::from_utf8(m.requests()[i].replies[0].bytes.clone()).unwrap());
    (answer, taken)
}

/// A crane's poll, its heartbeat moving, a hand-over whose ACK came 300 ms after the
/// strobe, then polls of the finished task.
fn crane() -> Vec<Recorded> {
    vec![
        read(0, "poll", "hb0"),
        write(2, "D0=1"),
        read(20, "poll", "hb0"),
        read(40, "poll", "hb1"),
        write(42, "D0=0"),
        read(60, "poll", "hb1 idle"),
        write(62, "task"),
        write(64, "STB=1"),
        read(70, "ack?", "0"),
        read(170, "ack?", "0"),
        read(370, "ack?", "1"),
        write(372, "STB=0"),
        read(380, "ack?", "0"),
        read(400, "poll", "hb0 running"),
        read(600, "poll", "hb0 done"),
    ]
}

#[test]
fn polls_are_answered_as_of_the_clock_whatever_their_number() {
    let mut m = Matcher::new(crane(), ms(50));
    // Three polls where the recording had two, before the heartbeat moved.
    assert_eq!(ask(&mut m, "poll", true, 1000), ("hb0".into(), Taken::Matched));
    assert_eq!(ask(&mut m, "poll", true, 1001), ("hb0".into(), Taken::Matched));
    assert_eq!(ask(&mut m, "D0=1", false, 1003), ("ok".into(), Taken::Matched));
    assert_eq!(ask(&mut m, "poll", true, 1010), ("hb0".into(), Taken::Matched));
    // One poll where the recording had two: the crane's answer as of then.
    assert_eq!(ask(&mut m, "poll", true, 1050), ("hb1".into(), Taken::Matched));
    assert_eq!(ask(&mut m, "D0=0", false, 1051), ("ok".into(), Taken::Matched));
    assert_eq!(m.counters(), Counters { matched: 6, ..Counters::default() });
}

#[test]
fn the_clock_waits_at_a_write_not_yet_made() {
    let mut m = Matcher::new(crane(), ms(50));
    ask(&mut m, "poll", true, 0);
    ask(&mut m, "D0=1", false, 2);
    ask(&mut m, "poll", true, 40);
    ask(&mut m, "D0=0", false, 42);
    // rackd is slow to hand the task over: the crane stays as it was before it, however long.
    assert_eq!(ask(&mut m, "poll", true, 5_000).0, "hb1 idle");
    assert_eq!(m.clock(ms(5_000)), ms(62));
    assert_eq!(ask(&mut m, "task", false, 5_001).1, Taken::Matched);
    assert_eq!(ask(&mut m, "STB=1", false, 5_002).1, Taken::Matched);
    // The late ACK stays late: 0 until 306 ms after the strobe, as recorded.
    assert_eq!(ask(&mut m, "ack?", true, 5_010).0, "0");
    assert_eq!(ask(&mut m, "ack?", true, 5_300).0, "0");
    assert_eq!(ask(&mut m, "ack?", true, 5_307).0, "0");
    assert_eq!(ask(&mut m, "ack?", true, 5_308).0, "1");
    // ... and stays 1 until rackd lowers the strobe.
    assert_eq!(ask(&mut m, "ack?", true, 9_000).0, "1");
    ask(&mut m, "STB=0", false, 9_001);
    assert_eq!(ask(&mut m, "ack?", true, 9_009).0, "0");
    assert_eq!(ask(&mut m, "poll", true, 9_030).0, "hb0 running");
    assert_eq!(m.counters().diverged(), 0);
}

#[test]
fn a_read_before_its_first_recorded_time_takes_the_first() {
    let mut m = Matcher::new(vec![read(100, "poll", "a"), read(200, "poll", "b")], ms(0));
    assert_eq!(ask(&mut m, "poll", true, 0).0, "a");
    assert_eq!(ask(&mut m, "poll", true, 150).0, "b", "clock 250 ms after the first request");
}

#[test]
fn writes_a_little_ahead_are_reordered_and_the_one_passed_is_owed() {
    let mut m = Matcher::new(crane(), ms(50));
    ask(&mut m, "poll", true, 0);
    ask(&mut m, "D0=1", false, 2);
    ask(&mut m, "poll", true, 41);
    // The task goes out before the heartbeat's answer (20 ms apart in the recording).
    assert_eq!(ask(&mut m, "task", false, 43), ("ok".into(), Taken::Reordered));
    assert_eq!(ask(&mut m, "D0=0", false, 44), ("ok".into(), Taken::Matched), "owed");
    assert_eq!(ask(&mut m, "STB=1", false, 45).1, Taken::Matched);
    assert_eq!(m.counters().diverged(), 0);
    assert_eq!(m.writes_not_made(), (0, 1));
}

#[test]
fn a_write_far_ahead_is_skipped_to_and_counted() {
    let mut m = Matcher::new(crane(), ms(10));
    ask(&mut m, "poll", true, 0);
    assert_eq!(ask(&mut m, "STB=1", false, 1), ("ok".into(), Taken::Skipped));
    assert_eq!(m.clock(ms(1)), ms(64), "the clock jumped to it");
    assert_eq!(m.writes_not_made(), (3, 1), "D0=1, D0=0 and the task passed over; STB=0 ahead");
    assert_eq!(ask(&mut m, "ack?", true, 400).0, "1");
    assert_eq!(m.counters(), Counters { matched: 2, skipped: 1, ..Counters::default() });
}

#[test]
fn a_read_a_little_ahead_of_the_write_due_is_answered_and_the_clock_stays() {
    let mut m = Matcher::new(crane(), ms(10));
    ask(&mut m, "poll", true, 0);
    ask(&mut m, "D0=1", false, 2);
    ask(&mut m, "poll", true, 40);
    // rackd checks ACK before it answers the heartbeat: 28 ms after D0=0 in the
    // recording, within a 30 ms tolerance.
    let mut m30 = Matcher::new(crane(), ms(30));
    for (key, read, at) in [("poll", true, 0), ("D0=1", false, 2), ("poll", true, 40)] {
        ask(&mut m30, key, read, at);
    }
    assert_eq!(ask(&mut m30, "ack?", true, 41), ("0".into(), Taken::Reordered));
    assert_eq!(m30.due(), Some(4), "D0=0 still due");
    assert_eq!(ask(&mut m30, "D0=0", false, 42).1, Taken::Matched);
    // Past the tolerance it is a divergence.
    assert_eq!(ask(&mut m, "ack?", true, 41), ("0".into(), Taken::Skipped));
}

#[test]
fn a_read_found_only_after_the_write_due_skips_there() {
    let mut m = Matcher::new(crane(), ms(10));
    ask(&mut m, "poll", true, 0);
    assert_eq!(ask(&mut m, "ack?", true, 1), ("0".into(), Taken::Skipped));
    assert_eq!(m.due(), Some(11), "STB=0 is due next");
}

#[test]
fn a_retry_gets_the_same_answer_and_a_stranger_none() {
    let mut m = Matcher::new(crane(), ms(10));
    ask(&mut m, "poll", true, 0);
    ask(&mut m, "D0=1", false, 2);
    assert_eq!(ask(&mut m, "D0=1", false, 200), ("ok".into(), Taken::Repeated));
    assert_eq!(ask(&mut m, "D7=9", false, 201), ("-".into(), Taken::Unanswered));
    assert_eq!(ask(&mut m, "what?", true, 202), ("-".into(), Taken::Unanswered));
    assert_eq!(m.counters().diverged(), 2);
}

#[test]
fn after_the_recording_the_last_answers_repeat() {
    let mut m = Matcher::new(crane(), ms(10));
    for (key, read, at) in [
        ("poll", true, 0),
        ("D0=1", false, 2),
        ("D0=0", false, 42),
        ("task", false, 62),
        ("STB=1", false, 64),
        ("STB=0", false, 372),
    ] {
        assert_ne!(ask(&mut m, key, read, at).1, Taken::Unanswered, "{key}");
    }
    assert!(!m.exhausted(ms(599)));
    assert_eq!(ask(&mut m, "poll", true, 599), ("hb0 running".into(), Taken::Matched));
    assert!(m.exhausted(ms(601)));
    assert_eq!(ask(&mut m, "poll", true, 700), ("hb0 done".into(), Taken::Repeated));
    assert_eq!(ask(&mut m, "D0=1", false, 701), ("ok".into(), Taken::Repeated));
    assert_eq!(ask(&mut m, "D0=7", false, 702), ("-".into(), Taken::Unanswered));
}

#[test]
fn an_empty_script_answers_nothing() {
    let mut m = Matcher::new(Vec::new(), ms(10));
    assert_eq!(ask(&mut m, "poll", true, 0), ("-".into(), Taken::Unanswered));
    assert_eq!(ask(&mut m, "w", false, 0), ("-".into(), Taken::Unanswered));
    assert!(m.exhausted(ms(0)));
}

/// The site: rackd answered the crane's heartbeat 0 (D0=1) and its 1 (D0=0), then handed a
/// task over, whose ACK came 400 ms late; then answered the heartbeat again (D0=1, D0=0).
fn late_ack_with_heartbeat() -> Vec<Recorded> {
    vec![
        read(0, "poll", "hb0"),
        write(2, "D0=1"),
        read(20, "poll", "hb1"),
        write(22, "D0=0"),
        write(44, "task"),
        write(45, "STB=1"),
        read(50, "ack?", "0"),
        read(450, "ack?", "1"),
        write(452, "STB=0"),
        read(458, "poll", "hb0 running"),
        write(459, "D0=1"),
        read(484, "poll", "hb1 running"),
        write(485, "D0=0"),
        read(508, "poll", "hb0 done"),
    ]
}

#[test]
fn a_write_the_device_already_holds_does_not_stop_the_clock() {
    let mut m = Matcher::new(late_ack_with_heartbeat(), ms(50));
    ask(&mut m, "poll", true, 0);
    assert_eq!(ask(&mut m, "D0=1", false, 2).1, Taken::Matched);
    // In the lab rackd hands the task over a poll earlier: it never reads the crane's 1,
    // so it never writes D0=0, and D0 still holds the 1 it wrote.
    assert_eq!(ask(&mut m, "task", false, 30).1, Taken::Reordered);
    assert_eq!(ask(&mut m, "STB=1", false, 31).1, Taken::Matched);
    assert_eq!(ask(&mut m, "ack?", true, 100).0, "0");
    assert_eq!(ask(&mut m, "ack?", true, 440).0, "1", "as late as recorded");
    assert_eq!(ask(&mut m, "STB=0", false, 441).1, Taken::Matched);
    // The crane's word is 0 and D0 holds 1: rackd has nothing to write. The recorded
    // D0=1 is not waited for once the clock reaches it (448 live).
    assert_eq!(ask(&mut m, "poll", true, 447).0, "hb0 running");
    assert_eq!(m.counters().in_place, 0, "not reached yet");
    assert_eq!(ask(&mut m, "poll", true, 470).0, "hb0 running");
    assert_eq!(m.counters().in_place, 1);
    assert_eq!(ask(&mut m, "poll", true, 480).0, "hb1 running", "the heartbeat moves on");
    assert_eq!(ask(&mut m, "D0=0", false, 481).1, Taken::Matched);
    assert_eq!(ask(&mut m, "poll", true, 510).0, "hb0 done");
    assert_eq!(m.counters().diverged(), 0);
    assert_eq!(m.writes_not_made(), (1, 0), "the D0=0 rackd had no reason to make");
}

#[test]
fn a_write_of_other_data_to_the_same_place_is_still_waited_for() {
    let mut m = Matcher::new(late_ack_with_heartbeat(), ms(50));
    ask(&mut m, "poll", true, 0);
    ask(&mut m, "D0=1", false, 2);
    ask(&mut m, "poll", true, 20);
    ask(&mut m, "D0=0", false, 22);
    ask(&mut m, "task", false, 44);
    ask(&mut m, "STB=1", false, 45);
    ask(&mut m, "ack?", true, 450);
    ask(&mut m, "STB=0", false, 452);
    // D0 holds 0 now: the recorded D0=1 is rackd's to make, and the clock waits for it.
    assert_eq!(ask(&mut m, "poll", true, 5_000).0, "hb0 running");
    assert_eq!(m.counters().in_place, 0);
    assert_eq!(ask(&mut m, "D0=1", false, 5_001).1, Taken::Matched);
}
