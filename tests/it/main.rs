//! rackd's integration tests, in one binary: the real server on 127.0.0.1:0 with a
//! temporary database, the real drivers against the real simulators over UDP, TCP and pty
//! pairs, real browsers and real outside tools. One binary links once and compiles the
//! shared [`support`] once; its tests run concurrently.
//!
//! One module per area. Suites that touch the store run on both engines, SQLite and
//! PostgreSQL (a throwaway cluster, [`support::postgres`]), as `rstest` cases named
//! `case_1_sqlite` and `case_2_postgres`: `cargo test --test it postgres` runs the
//! PostgreSQL side alone.

mod api;
mod browser;
mod bulk;
mod cancels;
mod capture;
mod clock;
mod crane;
mod docs;
mod events;
mod mc3e;
mod mewtocol;
mod modbus;
mod orders;
mod plc;
mod ppi;
mod reload;
mod security;
mod shelf;
mod sim_presets;
mod standby;
mod store;
mod support;
mod tags;
mod webhooks;
