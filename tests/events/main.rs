//! The live event stream end to end: the real server on 127.0.0.1:0 with a temporary
//! database, real WebSocket clients.

/// The engine these tests run the store on.
pub const ENGINE: rackd::store::Engine = rackd::store::Engine::Sqlite;

#[path = "../common/helpers.rs"]
mod helpers;
#[path = "../common/postgres.rs"]
mod postgres;
#[path = "../common/ws.rs"]
mod ws;

mod alarms;
mod replay;
mod slow;
mod stream;

#[path = "../common/events.rs"]
mod events;
pub use events::*;
