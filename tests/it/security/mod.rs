//! Issue 41, "hardened for a plant network": each finding of the review reproduced as an
//! attack or an accident over real sockets, one file per finding.

mod database_tls;
mod forwarding;
mod secrets;
mod tls_config;
