//! The error answers every operation can give, added to the OpenAPI document in one place,
//! so that the document promises exactly the statuses the server sends (a generated client
//! then has a type for each, and a contract fuzzer finds no undocumented status).
//!
//! They come from layers and extractors every route shares, not from the handlers:
//! - a path parameter that is not of its type (`/jobs/9223372036854775808`): 400 `bad_path`;
//! - a query that does not parse: 400 `bad_query`; a `token` query parameter anywhere but
//!   `GET /api/v1/ws`: 400 `token_in_query`; a query parameter the operation does not take,
//!   on every operation: 400 `bad_query` too ([`super::query`]); on an operation with a dry
//!   run, `dry_run` in the query and the body disagreeing: 400 `conflicting_dry_run`
//!   ([`super::dry_run`]);
//! - a request body that is not JSON: 400 `malformed_json`; one without
//!   `Content-Type: application/json`: 415; one over `server.body_limit_bytes`: 413;
//! - a key missing or unknown (once keys are configured): 401; a key whose role may not do
//!   this: 403 (only on operations that change something: every role may read);
//! - an address that sent `auth.max_failures` unknown keys: 429 with `Retry-After`;
//! - without keys (`api::keyless`): a `Host` that is not rackd's: 421; an `Origin` that is
//!   not rackd's: 403; a change not sent as `application/json`, body or not: 415;
//! - a request that runs past `server.request_timeout_secs`: 503 `timeout`.
//!
//! An operation that documents one of these statuses itself keeps its own description;
//! the new ones of issues 41 and 51 (`token_in_query`, `origin_not_allowed`, an unknown
//! query parameter, `conflicting_dry_run`) are added to it, and so is `too_many_failures`
//! to an operation's own 429 (`capture_busy`).

use utoipa::openapi::header::HeaderBuilder;
use utoipa::openapi::path::{Operation, ParameterIn};
use utoipa::openapi::{ContentBuilder, OpenApi, Ref, RefOr, Response, ResponseBuilder, Type};

/// Adds the shared error answers to every operation of `doc`.
pub fn complete(doc: &mut OpenApi) {
    for (path, item) in doc.paths.paths.iter_mut() {
        let websocket = path == "/api/v1/ws";
        let methods = [
            (&mut item.get, false),
            (&mut item.put, true),
            (&mut item.post, true),
            (&mut item.delete, true),
            (&mut item.patch, true),
        ];
        for (operation, changes) in methods {
            if let Some(operation) = operation.as_mut() {
                complete_operation(operation, changes, websocket);
            }
        }
    }
}

fn complete_operation(operation: &mut Operation, changes: bool, websocket: bool) {
    let within = |place: ParameterIn| {
        operation.parameters.iter().flatten().any(|p| matches!(p, RefOr::T(p) if p.parameter_in == place))
    };
    let (path, query) = (within(ParameterIn::Path), within(ParameterIn::Query));
    let dry_run = operation
        .parameters
        .iter()
        .flatten()
        .any(|p| matches!(p, RefOr::T(p) if p.parameter_in == ParameterIn::Query && p.name == "dry_run"));
    // An empty requirement list (`security(())`) marks a public operation.
    let keyed = operation.security.as_ref().is_none_or(|s| !s.is_empty() && !is_public(s));
    let body = operation.request_body.is_some();
    let responses = &mut operation.responses.responses;
    // Inserted unless the operation documents the status itself.
    let mut add = |status: &str, response: Response| {
        responses.entry(status.to_owned()).or_insert_with(|| RefOr::T(response));
    };
    match (path, query, body) {
        (_, _, true) => add(
            "400",
            error("`malformed_json`: the body is not JSON; `bad_path`: a path parameter is not of its type"),
        ),
        (true, true, false) => add(
            "400",
            error("`bad_path`: a path parameter is not of its type; `bad_query`: the query does not parse"),
        ),
        (true, false, false) => add("400", error("`bad_path`: a path parameter is not of its type")),
        (false, true, false) => add("400", error("`bad_query`: the query does not parse")),
        (false, false, false) => {}
    }
    if body {
        add("413", error("`body_too_large`: the body is over `server.body_limit_bytes`"));
        add("415", error("`unsupported_media_type`: the body is not sent as `application/json`"));
    } else if changes && keyed {
        add(
            "415",
            error(
                "`unsupported_media_type`: without API keys, a change must be sent with `Content-Type: application/json`, even with no body",
            ),
        );
    }
    if keyed {
        add(
            "401",
            error(
                "`unauthorized`: no key, or an unknown one (once keys are configured; unknown keys count toward `auth.max_failures`)",
            ),
        );
        if changes {
            add("403", error("`forbidden`: the key's role may not do this"));
        }
        add(
            "421",
            error(
                "`host_not_allowed`: without API keys, the `Host` names none of rackd's own names (see `server.allowed_hosts`)",
            ),
        );
        add("429", too_many());
    }
    add("503", error("`timeout`: the request took longer than `server.request_timeout_secs`"));
    // An operation's own 429 (`capture_busy`) says the shared one too.
    if let (true, Some(RefOr::T(own))) = (keyed, responses.get_mut("429")) {
        let shared = too_many();
        if !own.description.contains(&shared.description) {
            own.description = format!("{}; {}", own.description, shared.description);
            let seconds = retry_after("Seconds to wait before asking again");
            own.headers.insert("Retry-After".to_owned(), RefOr::T(seconds));
        }
    }
    // Added to what the operation says of these statuses, if it says anything.
    let mut also = |status: &str, text: &str| match responses.get_mut(status) {
        Some(RefOr::T(r)) if !r.description.contains(text) => {
            r.description = format!("{}; {text}", r.description)
        }
        Some(_) => {}
        None => drop(responses.insert(status.to_owned(), RefOr::T(error(text)))),
    };
    also("400", super::query::UNKNOWN_QUERY);
    if dry_run {
        also("400", super::dry_run::CONFLICTING);
    }
    if keyed {
        if !websocket {
            also(
                "400",
                "`token_in_query`: a `token` query parameter (only `GET /api/v1/ws` takes the key that way)",
            );
        }
        also(
            "403",
            "`origin_not_allowed`: without API keys, a request from a web page of another origin (see `server.allowed_hosts`)",
        );
    }
}

/// 429 `too_many_failures`, with its `Retry-After`.
fn too_many() -> Response {
    let mut response = error(
        "`too_many_failures`: this client address sent `auth.max_failures` unknown keys within \
         `auth.failure_window_secs`; every request is refused until the window ends, in `Retry-After` seconds",
    );
    response.headers.insert("Retry-After".to_owned(), RefOr::T(retry_after("Seconds until the window ends")));
    response
}

/// A `Retry-After` header: whole seconds, at least 1.
fn retry_after(description: &str) -> utoipa::openapi::header::Header {
    HeaderBuilder::new()
        .schema(Some(utoipa::openapi::ObjectBuilder::new().schema_type(Type::Integer).minimum(Some(1))))
        .description(Some(description))
        .build()
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
