//! Faults a simulated PLC can inject: drop a request, delay its reply, answer an end code,
//! or close the connection.
//!
//! A [`Faults`] value is shared as [`SharedFaults`] between the server and the test or
//! simulator driving it, and can be changed while the server runs. Scripted faults are used
//! first, one per request, so tests are deterministic; when the script is empty, the
//! standing settings apply (random drops at `drop_ratio`, a fixed `delay`, a sticky
//! `end_code`).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Faults shared between a server and its controller.
pub type SharedFaults = Arc<Mutex<Faults>>;

/// What to do to one request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Do not answer.
    Drop,
    /// Answer after this long (the answer reflects memory when the request arrived).
    Delay(Duration),
    /// Answer this end code (with error information) instead of executing the request.
    EndCode(u16),
    /// Close the TCP connection without answering (over UDP: same as [`Fault::Drop`]).
    Close,
}

/// The fault settings of a server.
#[derive(Clone, Debug, Default)]
pub struct Faults {
    /// Faults for the next requests, one per request, in order.
    pub script: VecDeque<Fault>,
    /// Fraction of requests (0.0..=1.0) dropped at random when the script is empty.
    pub drop_ratio: f64,
    /// Delay before every reply when the script is empty.
    pub delay: Duration,
    /// End code answered to every request when the script is empty.
    pub end_code: Option<u16>,
    /// Requests received so far (dropped ones included), for tests and simulators.
    pub requests_seen: u64,
}

impl Faults {
    /// Shares these settings.
    pub fn shared(self) -> SharedFaults {
        Arc::new(Mutex::new(self))
    }

    /// Queues a fault for an upcoming request.
    pub fn push(&mut self, fault: Fault) -> &mut Self {
        self.script.push_back(fault);
        self
    }

    /// The fault for the request just received, if any (counts the request).
    pub fn take_next(&mut self) -> Option<Fault> {
        self.requests_seen += 1;
        if let Some(fault) = self.script.pop_front() {
            return Some(fault);
        }
        if self.drop_ratio > 0.0 && rand::random::<f64>() < self.drop_ratio {
            return Some(Fault::Drop);
        }
        if let Some(code) = self.end_code {
            return Some(Fault::EndCode(code));
        }
        (!self.delay.is_zero()).then_some(Fault::Delay(self.delay))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_first_then_standing_settings() {
        let mut f = Faults { end_code: Some(0xC059), ..Faults::default() };
        f.push(Fault::Drop).push(Fault::Delay(Duration::from_millis(5)));
        assert_eq!(f.take_next(), Some(Fault::Drop));
        assert_eq!(f.take_next(), Some(Fault::Delay(Duration::from_millis(5))));
        assert_eq!(f.take_next(), Some(Fault::EndCode(0xC059)));
        f.end_code = None;
        assert_eq!(f.take_next(), None);
        f.drop_ratio = 1.0;
        assert_eq!(f.take_next(), Some(Fault::Drop));
        assert_eq!(f.requests_seen, 5);
    }
}
