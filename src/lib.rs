//! rackd: a warehouse control system.
//!
//! Layers, top to bottom (dependencies point down only): [`api`] (HTTP, OpenAPI, auth),
//! [`service`] (job intake, dispatch order), [`devices`] (what machines mean),
//! [`protocols`] (how to talk to PLCs), [`store`] (SQLite), and [`sim`] (simulated
//! machines, built on the protocol servers). [`domain`] holds the validated words every
//! layer shares.

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
