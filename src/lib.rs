//! rackd: a warehouse control system.
//!
//! Layers, top to bottom (dependencies point down only, and no module's children import
//! one another in a circle, checked by a test in `layering.rs`): [`cli`] (the command
//! line), [`app`] (building and running the service), [`api`] (HTTP, OpenAPI, the
//! dashboard), [`service`] (intake, the dispatcher, the device monitor, the event hub),
//! [`devices`] (what machines mean; they get work through a port the dispatcher
//! implements), [`config`] (all of the configuration, every device's settings included),
//! [`auth`] (keys and roles), [`store`] (SQLite or PostgreSQL, written by one writer under
//! the service), [`sim`] (simulated machines, built on the protocol servers), [`wire`] (the
//! machines' interfaces word by word, in the protocols' notations), [`protocols`] (how to
//! talk to PLCs, over one transport layer) and [`domain`] (the validated words every layer
//! shares). [`auth`], [`protocols`] and [`domain`] use no other layer, nor do [`files`] (how
//! rackd creates a file of its own) and [`redact`] (secrets out of the URLs it prints).
//!
//! No `unsafe` (Cargo.toml only denies it, for one module of the tests).

#![forbid(unsafe_code)]

pub mod api;
pub mod app;
pub mod auth;
pub mod capture;
pub mod cli;
pub mod config;
pub mod devices;
pub mod domain;
pub mod files;
pub mod protocols;
pub mod redact;
pub mod service;
pub mod sim;
pub mod store;
pub mod wire;

mod layering;
