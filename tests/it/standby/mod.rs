//! Hot standby on a real PostgreSQL (the throwaway cluster of [`crate::support::postgres`]):
//! the lease ([`cluster`]), two real nodes in one process ([`nodes`]), and failover of
//! real `rackd` processes killed with SIGKILL ([`failover`]), reloads ([`reload`]), and a
//! takeover with the webhook's files gone since the start ([`webhook_files`]).

mod cluster;
mod failover;
mod nodes;
mod reload;
mod webhook_files;
