//! Issue 41, "hardened for a plant network": each finding of the review reproduced as an
//! attack or an accident over real sockets against the real server, one file per finding.
//! Each test failed on the code before its fix.

mod audit;
mod connections;
mod database_tls;
mod failed_auth;
mod forwarding;
mod keyless;
mod metrics_labels;
mod secrets;
mod tls;
mod tls_config;
mod token_query;
