//! What the areas share: a running rackd ([`app`]), waiting with a deadline
//! ([`eventually`]), a WMS that keeps posting through faults ([`flow`]), the throwaway PostgreSQL cluster ([`postgres`]) and
//! servers a test owns to crash and fail over ([`pg_owned`]), a WebSocket client
//! ([`ws`]), a TCP proxy that can cut a link ([`proxy`]), certificates and an https
//! front for the TLS tests ([`tls`]), a webhook receiver ([`receiver`]), the Python
//! that runs the tests' Python libraries ([`python`]), where a child process listens as it
//! says itself ([`listening`]), a port held across a server's restarts ([`held`]) and a
//! SQLite VFS that fails the WAL's writes on command ([`faulty_vfs`]).

pub mod app;
pub mod faulty_vfs;
pub mod flow;
pub mod held;
pub mod listening;
pub mod machines;
pub mod node;
pub mod pg_owned;
pub mod port;
pub mod postgres;
pub mod proxy;
pub mod python;
pub mod receiver;
pub mod tls;
pub mod wait;
pub mod wire;
pub mod ws;

pub use app::*;
pub use wait::{eventually, eventually_blocking, eventually_every, try_eventually_every};
