//! The service layer: job intake, the dispatcher (which job next, on which device; cancels;
//! control state), the crane planner, the device monitor (device events and alarms) and the
//! event hub.

pub mod captures;
pub mod cluster;
pub mod dispatch;
pub mod events;
pub mod fleet;
pub mod intake;
pub mod monitor;
pub mod planner;
pub mod reload;
pub mod store_alarm;
pub mod webhooks;
