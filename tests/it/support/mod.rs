//! What the areas share: a running rackd ([`app`]), waiting with a deadline
//! ([`eventually`]), the throwaway PostgreSQL cluster ([`postgres`]), a WebSocket client
//! ([`ws`]) and a TCP proxy that can cut a link ([`proxy`]).

pub mod app;
pub mod postgres;
pub mod proxy;
pub mod wait;
pub mod ws;

pub use app::*;
pub use wait::{eventually, eventually_blocking, eventually_every, try_eventually_every};
