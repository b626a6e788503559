//! Issue 41, "hardened for a plant network": each finding of the review reproduced as the
//! attack (or the accident) it names, over real sockets against the real server, one file
//! per finding.

mod audit;
mod failed_auth;
mod keyless;
mod metrics_labels;
mod token_query;
