//! Hot standby on a real PostgreSQL (the throwaway cluster of [`crate::support::postgres`]):
//! the lease ([`cluster`]), two real nodes in one process ([`nodes`]), and failover of
//! real `rackd` processes killed with SIGKILL ([`failover`]), and reloads ([`reload`]).

mod cluster;
mod failover;
mod nodes;
mod reload;
