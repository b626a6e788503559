//! rackd: a warehouse control system.
//!
//! Layers, top to bottom (dependencies point down only): [`api`] (HTTP, OpenAPI, auth),
//! [`service`] (job intake), [`store`] (SQLite), [`protocols`] (how to talk to PLCs).
//! [`domain`] holds the validated words every layer shares.

pub mod api;
pub mod app;
pub mod auth;
pub mod cli;
pub mod config;
pub mod domain;
pub mod protocols;
pub mod service;
pub mod store;
