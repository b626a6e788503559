//! `dry_run`, taken the same way by every operation that has one (the bulk actions,
//! `POST /api/v1/config/reload`): in the query (`?dry_run=true`) or in the JSON body
//! (`{"dry_run": true}`), or both when they agree (issue 51: a user who learned one form on
//! one route ran the other route for real).
//!
//! Decisions:
//! - **Both places, not one**: the bulk actions took it in the body and the reload in the
//!   query, and both forms are in scripts and in the dashboard; refusing either would break
//!   them, and what matters is that no form is ignored.
//! - **Disagreeing is refused** (400 `conflicting_dry_run`), not settled: a request that
//!   says both "try" and "do it" says neither, and nothing is done.
//! - A parameter of another name (`?dryrun=`) is refused by [`super::query`] (400
//!   `bad_query`), a body field of another name by the body's own `deny_unknown_fields`.

use serde::Deserialize;
use utoipa::IntoParams;

use super::error::ApiError;

/// `?dry_run=`.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct DryRunParams {
    /// Only tell what would be done (as `dry_run` in the body; the two may not disagree).
    pub dry_run: Option<bool>,
}

/// Whether the request is a dry run: the query's `dry_run` and the body's, either or both.
pub fn dry_run(query: &DryRunParams, body: Option<bool>) -> Result<bool, ApiError> {
    match (query.dry_run, body) {
        (Some(q), Some(b)) if q != b => Err(ApiError::bad_request(
            "conflicting_dry_run",
            format!("dry_run is {q} in the query and {b} in the body: say it once, or the same in both"),
        )),
        (q, b) => Ok(q.or(b).unwrap_or(false)),
    }
}

/// What the 400 answer of an operation with a dry run says of it, in the OpenAPI document
/// ([`super::contract`]).
pub const CONFLICTING: &str = "`conflicting_dry_run`: `dry_run` in the query and in the body disagree";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn either_place_says_it_and_both_must_agree() {
        let q = |dry_run| DryRunParams { dry_run };
        assert!(!dry_run(&q(None), None).unwrap());
        assert!(dry_run(&q(Some(true)), None).unwrap());
        assert!(dry_run(&q(None), Some(true)).unwrap());
        assert!(dry_run(&q(Some(true)), Some(true)).unwrap());
        assert!(!dry_run(&q(Some(false)), Some(false)).unwrap());
        assert_eq!(dry_run(&q(Some(false)), Some(true)).unwrap_err().code, "conflicting_dry_run");
        assert_eq!(dry_run(&q(Some(true)), Some(false)).unwrap_err().code, "conflicting_dry_run");
    }
}
