//! Issue 41, "hardened for a plant network", and issue 51's findings on the newer surfaces:
//! each finding of the review reproduced as an attack or an accident over real sockets
//! against the real server (or the real binary), one file per finding. Each test failed on
//! the code before its fix.

mod audit;
mod certificate;
mod connections;
mod database_tls;
mod failed_auth;
mod files;
mod forwarding;
mod keyless;
mod metrics_labels;
mod query;
mod revoke;
mod secrets;
mod tls;
mod tls_config;
mod token_query;
mod urls;
