//! The service layer: job intake, and later scheduling, dispatch and the event bus.

pub mod dispatch;
pub mod events;
pub mod intake;
pub mod monitor;
