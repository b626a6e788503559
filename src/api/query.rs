//! The API refuses what it would ignore (issue 51): a query parameter an operation does not
//! take is answered 400 `bad_query`, naming it and those the operation takes, before the
//! handler runs, so that a typo (`?dryrun=true`, `?stat=failed`) or a parameter of
//! another route (`?dry_run=true` where `dry_run` was a body field) never runs a request
//! that ignores it.
//!
//! Decisions:
//! - **The list is the OpenAPI document's** ([`Known::of`]): the query parameters each
//!   operation documents, by method and route. One source, so a parameter a handler reads
//!   is one the document shows (the contract test holds the document to the server), and
//!   no list is kept by hand beside the handlers. `HEAD` takes what `GET` takes.
//! - **Every operation of the document**, `/healthz` and `/readyz` included; not the
//!   dashboard's files, `/docs` or `/openapi.json`, which are files, not operations, and
//!   where a query (a cache buster) changes nothing.
//! - **`bad_query`, the code of before**: the lists whose parameters were read into a
//!   struct refusing unknown fields already answered an unknown parameter so; now every
//!   operation does, and the message names the parameter.
//! - Checked after the key (a caller without one learns nothing of the parameters) and
//!   after `token` is taken out of the WebSocket's query ([`super::auth`]).
//! - A repeated parameter the operation takes is left to its extractor, as before.

use std::collections::{BTreeSet, HashMap};
use std::sync::Arc;

use axum::extract::{MatchedPath, Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::Response;
use utoipa::openapi::path::ParameterIn;
use utoipa::openapi::{OpenApi, RefOr};

use super::error::ApiError;

/// The query parameters each operation takes: by method and route (`/api/v1/jobs/{id}`).
#[derive(Debug, Default)]
pub struct Known(HashMap<(Method, String), BTreeSet<String>>);

impl Known {
    /// The operations of `doc` and the query parameters each documents.
    pub fn of(doc: &OpenApi) -> Known {
        let mut known = HashMap::new();
        for (path, item) in &doc.paths.paths {
            let methods = [
                (Method::GET, &item.get),
                (Method::PUT, &item.put),
                (Method::POST, &item.post),
                (Method::DELETE, &item.delete),
                (Method::PATCH, &item.patch),
            ];
            for (method, operation) in methods {
                let Some(operation) = operation else { continue };
                let names = operation
                    .parameters
                    .iter()
                    .flatten()
                    .filter_map(|p| match p {
                        RefOr::T(p) if p.parameter_in == ParameterIn::Query => Some(p.name.clone()),
                        _ => None,
                    })
                    .collect();
                known.insert((method, path.clone()), names);
            }
        }
        Known(known)
    }

    /// The parameters `method` on `route` takes, if it is an operation.
    fn of_operation(&self, method: &Method, route: &str) -> Option<&BTreeSet<String>> {
        let method = if method == Method::HEAD { &Method::GET } else { method };
        self.0.get(&(method.clone(), route.to_owned()))
    }
}

/// Middleware on every routed request: 400 `bad_query` for a query parameter the operation
/// does not take.
pub async fn refuse_unknown(
    State(known): State<Arc<Known>>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    let route = req.extensions().get::<MatchedPath>().map(|p| p.as_str().to_owned());
    let takes = route.as_deref().and_then(|route| known.of_operation(req.method(), route));
    if let (Some(takes), Some(query)) = (takes, req.uri().query()) {
        let unknown =
            form_urlencoded::parse(query.as_bytes()).map(|(k, _)| k).find(|k| !takes.contains(&**k));
        if let Some(name) = unknown {
            let takes = match takes.is_empty() {
                true => "none".to_owned(),
                false => takes.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", "),
            };
            return Err(ApiError::bad_request(
                "bad_query",
                format!(
                    "{} {} takes no query parameter `{name}` (it takes {takes}): it is refused rather than \
                     ignored",
                    req.method(),
                    route.unwrap_or_default()
                ),
            ));
        }
    }
    Ok(next.run(req).await)
}

/// What every operation's 400 answer says of it in the OpenAPI document
/// ([`super::contract`]).
pub const UNKNOWN_QUERY: &str =
    "`bad_query`: a query parameter the operation does not take (named in the message)";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_document_says_what_each_operation_takes() {
        let known = Known::of(&crate::api::openapi());
        let takes = |method: Method, route: &str| known.of_operation(&method, route).cloned();
        assert!(takes(Method::GET, "/api/v1/jobs").unwrap().contains("state"));
        assert_eq!(takes(Method::HEAD, "/api/v1/jobs"), takes(Method::GET, "/api/v1/jobs"));
        assert!(takes(Method::POST, "/api/v1/jobs/retry").unwrap().contains("dry_run"));
        assert!(takes(Method::POST, "/api/v1/jobs").unwrap().is_empty());
        assert!(takes(Method::GET, "/api/v1/ws").unwrap().contains("topics"));
        assert_eq!(takes(Method::GET, "/api/v1/nothing"), None);
    }
}
