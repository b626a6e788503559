//! Fault injection for the simulated server: lost requests, slow or garbled replies,
//! exceptions, wrong units, closed connections.

use std::time::Duration;

use rand::Rng;

use crate::protocols::modbus::exception::Exception;

/// Faults a server injects; change them at run time with
/// [`super::ServerHandle::set_faults`]. The default injects nothing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Faults {
    /// Fraction (0..=1) of requests ignored, as if lost on the way.
    pub drop_rate: f64,
    /// Wait before each reply.
    pub delay: Duration,
    /// Answer every request with this exception instead of performing it.
    pub exception: Option<Exception>,
    /// Fraction of replies preceded by random bytes (a separate datagram over UDP, bytes
    /// before the frame on a stream).
    pub garbage_rate: f64,
    /// Fraction of requests on a connection (TCP, RTU over TCP) answered by closing it.
    pub close_rate: f64,
    /// Answer with this unit id instead of the one asked (a reply from the wrong unit).
    pub reply_unit: Option<u8>,
    /// Send every reply twice.
    pub duplicate: bool,
}

/// What to do for one request, decided by rolling the dice of [`Faults`].
#[derive(Clone, Debug, Default)]
pub(crate) struct Plan {
    pub drop: bool,
    pub close: bool,
    pub delay: Duration,
    pub garbage: Option<Vec<u8>>,
    pub duplicate: bool,
    pub exception: Option<Exception>,
    pub reply_unit: Option<u8>,
}

impl Faults {
    /// True if no fault is set (the fast path).
    pub fn is_none(&self) -> bool {
        *self == Faults::default()
    }

    pub(crate) fn plan(&self) -> Plan {
        if self.is_none() {
            return Plan::default();
        }
        let mut rng = rand::rng();
        let mut roll = |p: f64| p > 0.0 && rng.random_bool(p.min(1.0));
        let drop = roll(self.drop_rate);
        let close = roll(self.close_rate);
        let garbage = roll(self.garbage_rate).then(|| {
            let mut rng = rand::rng();
            let len = rng.random_range(1..=12);
            (0..len).map(|_| rng.random()).collect()
        });
        Plan {
            drop,
            close,
            delay: self.delay,
            garbage,
            duplicate: self.duplicate,
            exception: self.exception,
            reply_unit: self.reply_unit,
        }
    }
}
