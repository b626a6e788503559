//! Hot standby on a real PostgreSQL (the throwaway cluster of [`crate::support::postgres`]):
//! the lease ([`cluster`]), two real nodes in one process ([`nodes`]), and failover of
//! real `rackd` processes killed with SIGKILL ([`failover`]), reloads ([`reload`]), and a
//! takeover with the webhook's files gone since the start ([`webhook_files`]), and a node of
//! the previous schema following and taking over from one of this schema, and back
//! ([`upgrade`]), and the pair through database failovers: a primary and its synchronous
//! replica, the active node riding one through, killed at one, and losing its lease in a
//! long one ([`database_failover`]).

mod cluster;
mod database_failover;
mod failover;
mod nodes;
mod reload;
mod upgrade;
mod webhook_files;
