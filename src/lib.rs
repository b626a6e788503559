//! rackd: a warehouse control system.
//!
//! Layers, top to bottom (dependencies point down only, checked by a test in
//! `layering.rs`): [`api`] (HTTP, OpenAPI, the dashboard), [`service`] (intake, the
//! dispatcher, the device monitor, the event hub), [`devices`] (what machines mean; they get
//! work through a port the dispatcher implements), [`protocols`] (how to talk to PLCs, over
//! one transport layer), [`store`] (SQLite, under the service), and [`sim`] (simulated
//! machines, built on the protocol servers). [`wire`] (the machines' interfaces word by
//! word) and [`domain`] (the validated words every layer shares) are leaves.

pub mod api;
pub mod app;
pub mod auth;
pub mod cli;
pub mod config;
pub mod devices;
pub mod domain;
pub mod protocols;
pub mod service;
pub mod sim;
pub mod store;
pub mod wire;

mod layering;
