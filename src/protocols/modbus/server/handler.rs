//! What a server does with a decoded request: the seam where simulators add behaviour.

use crate::protocols::modbus::exception::Exception;
use crate::protocols::modbus::pdu::{Request, Response};

/// Answers decoded requests for a server. [`super::Bank`] implements it by reading and
/// writing its tables; a device simulator wraps a bank in its own handler to observe or
/// refuse requests (count writes into a busy task slot, answer exception 06 while busy,
/// start work when a task id is written) and then delegates to the bank.
///
/// Called for every request addressed to the server's unit (over TCP and UDP also units 0
/// and 255, which address the device itself), and for RTU broadcasts (unit 0) whose reply
/// is then discarded. Runs under no lock of the server's own; keep it short,
/// it is on the reply path.
pub trait Handler: Send + Sync + 'static {
    /// Performs `request` sent to `unit`, or refuses it with an exception.
    fn handle(&self, unit: u8, request: &Request) -> Result<Response, Exception>;
}
