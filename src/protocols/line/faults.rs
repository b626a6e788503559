//! Faults a simulated MEWTOCOL or PPI device injects: drop a request, delay the reply, send
//! noise before it, answer an error code, or (PPI) lose the short acknowledgement.
//!
//! Scripted faults are used first, one per request, so tests are deterministic; when the
//! script is empty the standing settings apply.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Faults shared between a server and whoever drives it.
pub type SharedFaults = Arc<Mutex<Faults>>;

/// One scripted fault.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Do not answer at all.
    Drop,
    /// Answer after this long.
    Delay(Duration),
    /// Send these bytes before the answer.
    Garbage(Vec<u8>),
    /// Answer with this device error code instead of executing the request.
    Error(u16),
    /// PPI: do not send the short acknowledgement `E5` (the request is not executed).
    DropAck,
}

/// What the server does to one request.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Plan {
    /// Leave the request unanswered.
    pub drop: bool,
    /// PPI: leave the acknowledgement out.
    pub drop_ack: bool,
    /// Wait this long before answering.
    pub delay: Duration,
    /// Noise sent before the answer.
    pub garbage: Option<Vec<u8>>,
    /// Device error code answered instead of executing.
    pub error: Option<u16>,
}

/// The fault settings of a server.
#[derive(Clone, Debug, Default)]
pub struct Faults {
    /// Faults for the next requests, one per request, in order.
    pub script: VecDeque<Fault>,
    /// Fraction (0..=1) of requests dropped at random.
    pub drop_ratio: f64,
    /// Fraction (0..=1) of answers preceded by random noise.
    pub garbage_ratio: f64,
    /// Delay before every answer.
    pub delay: Duration,
    /// Error code answered to every request.
    pub error: Option<u16>,
    /// Requests received so far (dropped ones included).
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

    /// The plan for the request just received (counts the request).
    pub fn take_next(&mut self) -> Plan {
        self.requests_seen += 1;
        if let Some(fault) = self.script.pop_front() {
            let mut plan = Plan::default();
            match fault {
                Fault::Drop => plan.drop = true,
                Fault::DropAck => plan.drop_ack = true,
                Fault::Delay(d) => plan.delay = d,
                Fault::Garbage(g) => plan.garbage = Some(g),
                Fault::Error(code) => plan.error = Some(code),
            }
            return plan;
        }
        let garbage = (self.garbage_ratio > 0.0 && rand::random::<f64>() < self.garbage_ratio)
            .then(|| (0..8).map(|_| rand::random::<u8>()).collect());
        Plan {
            drop: self.drop_ratio > 0.0 && rand::random::<f64>() < self.drop_ratio,
            drop_ack: false,
            delay: self.delay,
            garbage,
            error: self.error,
        }
    }
}

/// Locks shared faults and plans the next request (a poisoned lock is still used).
pub fn plan(faults: &SharedFaults) -> Plan {
    faults.lock().unwrap_or_else(|p| p.into_inner()).take_next()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_first_then_standing_settings() {
        let mut f = Faults { error: Some(63), ..Faults::default() };
        f.push(Fault::Drop).push(Fault::Garbage(vec![1, 2]));
        assert!(f.take_next().drop);
        assert_eq!(f.take_next().garbage, Some(vec![1, 2]));
        let p = f.take_next();
        assert_eq!((p.drop, p.error), (false, Some(63)));
        f.drop_ratio = 1.0;
        assert!(f.take_next().drop);
        assert_eq!(f.requests_seen, 4);
    }
}
