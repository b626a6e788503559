//! Integration tests of the HTTP API: the real server on 127.0.0.1:0 with a temporary
//! database, spoken to over real HTTP. The suites that touch the store run on both engines
//! (`case_1_sqlite`, `case_2_postgres`); the OpenAPI document, the CLI, the container, the
//! schemathesis run, the logs and the metrics' parsers run once.

mod alarms;
mod auth;
mod cli;
mod container;
mod contract;
mod counts;
pub(crate) mod demo;
mod errors;
mod inventory;
mod jobs;
mod lifecycle;
mod logs;
pub mod metrics;
mod openapi;
mod paging;
mod stats;
pub(crate) mod waiting;
