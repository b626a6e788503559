//! The API and event-log suites again, on PostgreSQL: the same test files as
//! `tests/api` and `tests/events`, compiled with `ENGINE = Postgres`, against a throwaway
//! cluster this test process starts itself (see `tests/common/postgres.rs`; it needs
//! Debian's `postgresql` package, which `.ci/run` installs).
//!
//! The suites that do not touch the store (the OpenAPI document, the CLI, the container,
//! the schemathesis run, logs) run once, in `tests/api`.

/// The engine these tests run the store on.
pub const ENGINE: rackd::store::Engine = rackd::store::Engine::Postgres;

#[path = "../common/helpers.rs"]
mod helpers;
#[path = "../common/postgres.rs"]
mod postgres;
#[path = "../common/proxy.rs"]
mod proxy;
#[path = "../common/ws.rs"]
mod ws;

mod cluster;
mod failover;
mod nodes;

#[path = "../api/alarms.rs"]
mod api_alarms;
#[path = "../api/auth.rs"]
mod auth;
#[path = "../api/demo.rs"]
mod demo;
#[path = "../api/errors.rs"]
mod errors;
#[path = "../api/inventory.rs"]
mod inventory;
#[path = "../api/jobs.rs"]
mod jobs;
#[path = "../api/lifecycle.rs"]
mod lifecycle;
#[path = "../api/paging.rs"]
mod paging;
#[path = "../api/stats.rs"]
mod stats;
#[path = "../api/waiting.rs"]
mod waiting;

#[path = "../common/events.rs"]
mod events;
pub use events::*;

#[path = "../events/alarms.rs"]
mod alarms;
#[path = "../events/replay.rs"]
mod replay;
#[path = "../events/stream.rs"]
mod stream;
