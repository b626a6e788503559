//! What the areas share: a running rackd ([`app`]), waiting with a deadline
//! ([`eventually`]), the throwaway PostgreSQL cluster ([`postgres`]), a WebSocket client
//! ([`ws`]), a TCP proxy that can cut a link ([`proxy`]), and certificates and an https
//! front for the TLS tests ([`tls`]).

pub mod app;
pub mod node;
pub mod postgres;
pub mod proxy;
pub mod receiver;
pub mod tls;
pub mod wait;
pub mod ws;

pub use app::*;
pub use wait::{eventually, eventually_blocking, eventually_every, try_eventually_every};
