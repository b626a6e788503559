//! The simulated crane's link: standing faults, dropping it once, taking it down and up,
//! cutting it after a chosen write, and the requests seen.

use crate::protocols::faults::{Fault, Faults};

use super::CraneSim;

impl CraneSim {
    /// Takes the link down (as `link off`) right after the next write of the WCS that
    /// leaves D register `n` at `value`; that write is carried out and answered, nothing
    /// after it until [`CraneSim::set_link`] brings the link back.
    pub fn cut_link_after(&self, n: u32, value: u16) {
        *self.cut.lock().unwrap_or_else(|p| p.into_inner()) = Some((n, value));
    }

    /// Whether an armed [`CraneSim::cut_link_after`] has fired.
    pub fn link_cut(&self) -> bool {
        self.cut.lock().unwrap_or_else(|p| p.into_inner()).is_none()
    }

    /// Sets the standing link faults (`rackd sim crane`'s fault flags).
    pub fn set_faults(&self, faults: Faults) {
        *self.drop_rate.lock().unwrap_or_else(|p| p.into_inner()) = faults.drop_rate;
        if let Some(s) = &self.server {
            s.faults().set(faults);
        }
    }

    /// Closes the TCP connection (loses the next request over UDP).
    pub fn drop_link(&self) {
        if let Some(s) = &self.server {
            s.faults().push(Fault::Close);
        }
    }

    /// Ignores every request (`false`) or answers again (`true`, at the configured drop
    /// rate).
    pub fn set_link(&self, up: bool) {
        let configured = *self.drop_rate.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(s) = &self.server {
            s.faults().update(|f| f.drop_rate = if up { configured } else { 1.0 });
        }
    }

    /// Requests that reached the crane's server so far, dropped ones included (0 once it is
    /// shut down). Tests wait on it to know rackd has polled the crane again, instead of
    /// sleeping a fixed time before asserting that something did not happen.
    pub fn requests_seen(&self) -> u64 {
        self.server.as_ref().map_or(0, |s| s.faults().requests_seen())
    }
}
