//! Issue 41, "hardened for a plant network": each finding of the review reproduced as an
//! attack or an accident over real sockets, one file per finding. Each test failed on the
//! code before its fix.

mod connections;
mod database_tls;
mod forwarding;
mod secrets;
mod tls;
mod tls_config;
