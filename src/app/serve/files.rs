//! The open-files limit, which bounds the connections more surely than any setting: a
//! process out of file descriptors can accept nothing, not even `/healthz`.
//!
//! At its start the server raises its soft `RLIMIT_NOFILE` to the hard one (systemd's
//! default is 1024 soft, 524288 hard; a container's is its runtime's), as servers that
//! expect many clients do, and serves at most the limit less [`RESERVE`] connections,
//! whatever `server.max_connections` says (with a warning when it says more).

/// Descriptors kept for everything that is not a client's connection: the database and
/// its journal files, the devices' and simulators' sockets, logs, the runtime's own.
/// The demo site holds about 40 of them.
pub(super) const RESERVE: u64 = 128;

/// The most connections to serve at once: `max_connections`, or less if the open-files
/// limit cannot hold them.
pub(super) fn cap(max_connections: usize) -> usize {
    let Some(limit) = raise() else { return max_connections };
    let room = usize::try_from(limit.saturating_sub(RESERVE)).unwrap_or(usize::MAX).max(1);
    if max_connections > room {
        tracing::warn!(
            max_connections,
            open_files_limit = limit,
            serving = room,
            "server.max_connections is more than the open-files limit leaves room for; raise the limit \
             (LimitNOFILE= in a systemd unit, ulimits in compose, ulimit -n) or lower the setting"
        );
        return room;
    }
    max_connections
}

/// Raises the soft limit to the hard one; the soft limit in force after, if there is one.
#[cfg(target_os = "linux")]
fn raise() -> Option<u64> {
    use rustix::process::{Resource, getrlimit, setrlimit};
    let mut limit = getrlimit(Resource::Nofile);
    let soft = limit.current?;
    match limit.maximum {
        Some(hard) if hard > soft => {
            limit.current = Some(hard);
            match setrlimit(Resource::Nofile, limit) {
                Ok(()) => Some(hard),
                Err(e) => {
                    tracing::debug!(error = %e, "raising the open-files limit");
                    Some(soft)
                }
            }
        }
        _ => Some(soft),
    }
}

#[cfg(not(target_os = "linux"))]
fn raise() -> Option<u64> {
    None
}
