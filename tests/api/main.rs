//! Integration tests of the HTTP API: the real server on 127.0.0.1:0 with a temporary
//! SQLite file, spoken to over real HTTP.

mod alarms;
mod auth;
mod cli;
mod container;
mod contract;
mod demo;
mod errors;
/// The engine these tests run the store on.
pub const ENGINE: rackd::store::Engine = rackd::store::Engine::Sqlite;

#[path = "../common/helpers.rs"]
mod helpers;
mod inventory;
mod jobs;
mod lifecycle;
mod logs;
mod metrics;
mod openapi;
mod paging;
#[path = "../common/postgres.rs"]
mod postgres;
mod stats;
mod waiting;
#[path = "../common/ws.rs"]
mod ws;
