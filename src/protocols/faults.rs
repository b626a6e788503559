//! One fault vocabulary for every simulated device: the Modbus, MC 3E, MEWTOCOL and PPI
//! servers inject the same faults under the same names, and every `rackd sim` takes them as
//! the same flags.
//!
//! A server holds a [`SharedFaults`]: standing settings ([`Faults`], rates rolled per
//! request) plus a script of one-off faults ([`Fault`]) used first, one per request, so tests
//! are deterministic. Whoever drives the server (a test, a simulator's console) keeps a clone
//! and changes either while it runs.
//!
//! # Meanings where a protocol lacks the notion
//! - `close`: the connection being served is closed instead of answering (TCP; a served
//!   serial stream ends as well). Over UDP the request is dropped.
//! - `wrong_id`: the reply carries another transaction id (Modbus TCP, UDP) or PDU reference
//!   (PPI). MC 3E, MEWTOCOL and Modbus RTU frames carry none: no effect there.
//! - `wrong_unit`: the reply comes from this unit (Modbus), station (MEWTOCOL) or address
//!   (PPI). MC 3E routes are not units: no effect there.
//! - `device_error`: the code in the protocol's own numbering: a Modbus exception (low
//!   byte), an MC end code, a MEWTOCOL error code (below 100), a PPI item return code below
//!   0x100 or a refusal as error class x 256 + code (0x8500).
//! - [`Fault::DropAck`] is PPI's lost short acknowledgement; elsewhere it is a drop.
//! - `jitter`: each reply waits `delay` plus a draw from an exponential distribution of
//!   mean `jitter`, cut at [`JITTER_CUT`] times the mean: the long tail of a busy PLC's
//!   turnaround, bounded, so that a client whose timeout is above `delay + 10 × jitter`
//!   gets every reply in time and one whose timeout is below it meets late replies.
//! - `late`: the first request after the setting is made is answered this much later than
//!   `delay`, once; every later one after `delay` alone. A PLC that was busy once and then
//!   keeps its usual turnaround: with `late` beyond the client's timeout, the client's
//!   retry gets a late answer *and* a prompt one, the duplicate that must not be taken for
//!   the next request's answer (tokio-modbus issue #324).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use rand::Rng;

/// Standing fault settings; the default injects nothing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Faults {
    /// Fraction (0..=1) of requests left unanswered, as if lost on the way.
    pub drop_rate: f64,
    /// Wait before each reply; longer than the client's timeout, every reply is late.
    pub delay: Duration,
    /// Mean of a random wait added to `delay` for each reply: exponentially distributed
    /// (most replies quick, a few slow), cut at [`JITTER_CUT`] times the mean so that a
    /// client's timeout can cover the slowest (see the module documentation).
    pub jitter: Duration,
    /// Extra wait before the first reply only (zero: none); see the module docs.
    pub late: Duration,
    /// Fraction (0..=1) of replies preceded by random bytes (a separate datagram on UDP).
    pub garbage_rate: f64,
    /// Fraction (0..=1) of requests answered by closing the connection.
    pub close_rate: f64,
    /// Fraction (0..=1) of replies sent twice.
    pub duplicate_rate: f64,
    /// Fraction (0..=1) of replies with a wrong transaction id or PDU reference.
    pub wrong_id_rate: f64,
    /// Answer as this unit / station instead of the one asked.
    pub wrong_unit: Option<u8>,
    /// Answer every request with this device error code instead of carrying it out.
    pub device_error: Option<u16>,
}

/// The slowest jitter, in means: an exponential draw is cut here (P > 10 means is 1 in
/// 22,000).
pub const JITTER_CUT: u32 = 10;

/// A draw of the jitter of mean `mean` (see [`Faults::jitter`]).
fn jitter(mean: Duration, rng: &mut impl Rng) -> Duration {
    if mean.is_zero() {
        return Duration::ZERO;
    }
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    mean.mul_f64((-u.ln()).min(f64::from(JITTER_CUT)))
}

/// Why fault settings cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{name} must be a fraction between 0 and 1, got {value}")]
pub struct BadRate {
    /// The setting.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
}

impl Faults {
    /// Checks that every rate is a fraction.
    pub fn check(&self) -> Result<(), BadRate> {
        let rates = [
            ("drop_rate", self.drop_rate),
            ("garbage_rate", self.garbage_rate),
            ("close_rate", self.close_rate),
            ("duplicate_rate", self.duplicate_rate),
            ("wrong_id_rate", self.wrong_id_rate),
        ];
        match rates.into_iter().find(|(_, p)| !(0.0..=1.0).contains(p)) {
            Some((name, value)) => Err(BadRate { name, value }),
            None => Ok(()),
        }
    }

    /// The plan for one request, rolling the dice of each rate.
    fn roll(&self) -> Plan {
        let mut rng = rand::rng();
        let mut roll = |p: f64| p > 0.0 && rng.random_bool(p.min(1.0));
        let drop = roll(self.drop_rate);
        let close = roll(self.close_rate);
        let garbage = roll(self.garbage_rate);
        let duplicate = roll(self.duplicate_rate);
        let wrong_id = roll(self.wrong_id_rate);
        let garbage = garbage.then(|| {
            let mut rng = rand::rng();
            let len = rng.random_range(1..=12);
            (0..len).map(|_| rng.random()).collect()
        });
        Plan {
            drop,
            drop_ack: false,
            close,
            delay: self.delay + jitter(self.jitter, &mut rand::rng()),
            garbage,
            duplicate,
            wrong_id,
            wrong_unit: self.wrong_unit,
            device_error: self.device_error,
        }
    }
}

/// One scripted fault, for the next request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Do not answer.
    Drop,
    /// PPI: do not send the short acknowledgement `E5` (the request is not carried out).
    DropAck,
    /// Answer after this long (the answer reflects memory when the request arrived).
    Delay(Duration),
    /// Send these bytes before the answer.
    Garbage(Vec<u8>),
    /// Close the connection without answering.
    Close,
    /// Send the answer twice.
    Duplicate,
    /// Answer with a wrong transaction id or PDU reference.
    WrongId,
    /// Answer as this unit / station.
    WrongUnit(u8),
    /// Answer this device error code instead of carrying the request out.
    DeviceError(u16),
}

/// What a server does to one request.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Plan {
    /// Leave the request unanswered.
    pub drop: bool,
    /// PPI: leave the acknowledgement out (and the request undone).
    pub drop_ack: bool,
    /// Close the connection instead of answering.
    pub close: bool,
    /// Wait this long before answering.
    pub delay: Duration,
    /// Noise sent before the answer.
    pub garbage: Option<Vec<u8>>,
    /// Send the answer twice.
    pub duplicate: bool,
    /// Answer with a wrong transaction id or PDU reference.
    pub wrong_id: bool,
    /// Answer as this unit / station.
    pub wrong_unit: Option<u8>,
    /// Device error code answered instead of carrying the request out.
    pub device_error: Option<u16>,
}

impl Plan {
    /// True when the request is not answered at all (dropped, acknowledgement lost, or the
    /// connection closed).
    pub fn unanswered(&self) -> bool {
        self.drop || self.drop_ack || self.close
    }
}

impl From<Fault> for Plan {
    fn from(fault: Fault) -> Plan {
        let mut plan = Plan::default();
        match fault {
            Fault::Drop => plan.drop = true,
            Fault::DropAck => plan.drop_ack = true,
            Fault::Delay(d) => plan.delay = d,
            Fault::Garbage(g) => plan.garbage = Some(g),
            Fault::Close => plan.close = true,
            Fault::Duplicate => plan.duplicate = true,
            Fault::WrongId => plan.wrong_id = true,
            Fault::WrongUnit(unit) => plan.wrong_unit = Some(unit),
            Fault::DeviceError(code) => plan.device_error = Some(code),
        }
        plan
    }
}

#[derive(Debug, Default)]
struct State {
    faults: Faults,
    script: VecDeque<Fault>,
    requests_seen: u64,
    /// The `late` reply of the standing settings was planned.
    late_done: bool,
}

/// The fault settings of a running server, shared with whoever drives it.
#[derive(Clone, Debug, Default)]
pub struct SharedFaults(Arc<Mutex<State>>);

impl SharedFaults {
    /// Shares these standing settings, with an empty script.
    pub fn new(faults: Faults) -> Self {
        SharedFaults(Arc::new(Mutex::new(State { faults, ..State::default() })))
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // A panic elsewhere while holding the lock leaves plain data: still usable.
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Replaces the standing settings from the next request on (the script stays).
    pub fn set(&self, faults: Faults) {
        let mut state = self.state();
        state.faults = faults;
        state.late_done = false;
    }

    /// The standing settings.
    pub fn get(&self) -> Faults {
        self.state().faults.clone()
    }

    /// Changes the standing settings in place.
    pub fn update(&self, change: impl FnOnce(&mut Faults)) {
        let mut state = self.state();
        let late = state.faults.late;
        change(&mut state.faults);
        if state.faults.late != late {
            state.late_done = false;
        }
    }

    /// Queues a fault for an upcoming request.
    pub fn push(&self, fault: Fault) -> &Self {
        self.state().script.push_back(fault);
        self
    }

    /// Requests planned so far (dropped ones included).
    pub fn requests_seen(&self) -> u64 {
        self.state().requests_seen
    }

    /// The plan for the request just received: the next scripted fault, or else the
    /// standing settings. Counts the request.
    pub fn plan(&self) -> Plan {
        let mut state = self.state();
        state.requests_seen += 1;
        if let Some(fault) = state.script.pop_front() {
            return fault.into();
        }
        if state.faults == Faults::default() {
            return Plan::default();
        }
        let mut plan = state.faults.roll();
        if !state.faults.late.is_zero() && !state.late_done {
            state.late_done = true;
            plan.delay += state.faults.late;
        }
        plan
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_first_then_standing_settings() {
        let faults = SharedFaults::new(Faults { device_error: Some(63), ..Faults::default() });
        faults
            .push(Fault::Drop)
            .push(Fault::Garbage(vec![1, 2]))
            .push(Fault::Delay(Duration::from_millis(5)));
        assert!(faults.plan().drop);
        assert_eq!(faults.plan().garbage, Some(vec![1, 2]));
        let delayed = faults.plan();
        assert_eq!((delayed.delay, delayed.device_error), (Duration::from_millis(5), None), "one fault");
        let standing = faults.plan();
        assert_eq!((standing.drop, standing.device_error), (false, Some(63)));
        faults.update(|f| f.drop_rate = 1.0);
        assert!(faults.plan().unanswered());
        faults.set(Faults::default());
        assert_eq!(faults.plan(), Plan::default());
        assert_eq!(faults.requests_seen(), 6);
    }

    #[test]
    fn a_late_reply_comes_once_then_the_usual_turnaround() {
        let ms = Duration::from_millis;
        let faults = SharedFaults::new(Faults { delay: ms(30), late: ms(1100), ..Faults::default() });
        assert_eq!(faults.plan().delay, ms(1130), "late once");
        assert_eq!(faults.plan().delay, ms(30));
        assert_eq!(faults.plan().delay, ms(30));
        faults.update(|f| f.late = ms(500));
        assert_eq!(faults.plan().delay, ms(530), "a new lateness fires again");
        assert_eq!(faults.plan().delay, ms(30));
    }

    #[test]
    fn jitter_is_a_bounded_long_tail_around_its_mean() {
        let faults =
            Faults { delay: Duration::from_millis(5), jitter: Duration::from_millis(2), ..Faults::default() };
        let delays: Vec<Duration> = (0..20_000).map(|_| faults.roll().delay).collect();
        let min = delays.iter().min().unwrap();
        let max = delays.iter().max().unwrap();
        let mean = delays.iter().sum::<Duration>() / delays.len() as u32;
        assert!(*min >= Duration::from_millis(5), "never below the delay: {min:?}");
        assert!(*max <= Duration::from_millis(5 + 20), "cut at ten means: {max:?}");
        assert!(*max > Duration::from_millis(5 + 8), "a long tail: {max:?}");
        let ms = mean.as_secs_f64() * 1000.0;
        assert!((6.8..7.2).contains(&ms), "mean about delay + jitter: {ms}");
    }

    #[test]
    fn rates_are_fractions() {
        assert!(Faults::default().check().is_ok());
        let bad = Faults { wrong_id_rate: 1.5, ..Faults::default() };
        assert_eq!(bad.check(), Err(BadRate { name: "wrong_id_rate", value: 1.5 }));
        let always = Faults { duplicate_rate: 1.0, wrong_id_rate: 1.0, close_rate: 1.0, ..Faults::default() };
        let plan = always.roll();
        assert!(plan.duplicate && plan.wrong_id && plan.close && !plan.drop);
    }
}
