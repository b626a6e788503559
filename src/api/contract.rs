//! The error answers every operation can give, added to the OpenAPI document in one place,
//! so that the document promises exactly the statuses the server sends (a generated client
//! then has a type for each, and a contract fuzzer finds no undocumented status).
//!
//! They come from layers and extractors every route shares, not from the handlers:
//! - a path parameter that is not of its type (`/jobs/9223372036854775808`): 400 `bad_path`;
//! - a query that does not parse: 400 `bad_query`;
//! - a request body that is not JSON: 400 `malformed_json`; one without
//!   `Content-Type: application/json`: 415; one over `server.body_limit_bytes`: 413;
//! - a key missing or unknown (once keys are configured): 401; a key whose role may not do
//!   this: 403 (only on operations that change something: every role may read);
//! - a request that runs past `server.request_timeout_secs`: 503 `timeout`.
//!
//! An operation that documents one of these statuses itself keeps its own description.

use utoipa::openapi::path::{Operation, ParameterIn};
use utoipa::openapi::{ContentBuilder, OpenApi, Ref, RefOr, Response, ResponseBuilder};

/// Adds the shared error answers to every operation of `doc`.
pub fn complete(doc: &mut OpenApi) {
    for item in doc.paths.paths.values_mut() {
        let methods = [
            (&mut item.get, false),
            (&mut item.put, true),
            (&mut item.post, true),
            (&mut item.delete, true),
            (&mut item.patch, true),
        ];
        for (operation, changes) in methods {
            if let Some(operation) = operation.as_mut() {
                complete_operation(operation, changes);
            }
        }
    }
}

fn complete_operation(operation: &mut Operation, changes: bool) {
    let within = |place: ParameterIn| {
        operation.parameters.iter().flatten().any(|p| matches!(p, RefOr::T(p) if p.parameter_in == place))
    };
    let (path, query) = (within(ParameterIn::Path), within(ParameterIn::Query));
    // An empty requirement list (`security(())`) marks a public operation.
    let keyed = operation.security.as_ref().is_none_or(|s| !s.is_empty() && !is_public(s));
    let body = operation.request_body.is_some();
    let mut add = |status: &str, text: &str| {
        operation.responses.responses.entry(status.to_owned()).or_insert_with(|| RefOr::T(error(text)));
    };
    match (path, query, body) {
        (_, _, true) => add(
            "400",
            "`malformed_json`: the body is not JSON; `bad_path`: a path parameter is not of its type",
        ),
        (true, true, false) => add(
            "400",
            "`bad_path`: a path parameter is not of its type; `bad_query`: the query does not parse",
        ),
        (true, false, false) => add("400", "`bad_path`: a path parameter is not of its type"),
        (false, true, false) => add("400", "`bad_query`: the query does not parse"),
        (false, false, false) => {}
    }
    if body {
        add("413", "`body_too_large`: the body is over `server.body_limit_bytes`");
        add("415", "`unsupported_media_type`: the body is not sent as `application/json`");
    }
    if keyed {
        add("401", "`unauthorized`: no key, or an unknown one (once keys are configured)");
        if changes {
            add("403", "`forbidden`: the key's role may not do this");
        }
    }
    add("503", "`timeout`: the request took longer than `server.request_timeout_secs`");
}

/// Whether a security list is the `security(())` of a public operation: one empty requirement.
fn is_public(requirements: &[utoipa::openapi::security::SecurityRequirement]) -> bool {
    let empty = utoipa::openapi::security::SecurityRequirement::default();
    requirements.iter().all(|r| *r == empty)
}

/// An error answer with the JSON error body.
fn error(description: &str) -> Response {
    let content = ContentBuilder::new().schema(Some(Ref::from_schema_name("ErrorBody"))).build();
    ResponseBuilder::new().description(description).content("application/json", content).build()
}
