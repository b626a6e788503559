//! `/api/v1/whoami`: who the presented key is, so a page shows only what it may use.
//!
//! With no keys configured every request is let through (rackd then serves loopback only),
//! so the answer is `anonymous` with the admin role: everything is allowed.

use axum::Extension;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::ErrorBody;
use super::extract::Json;
use super::state::AppState;
use crate::auth::{Principal, Role};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(whoami))
}

/// A key's role, as the API writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum RoleName {
    /// Reads only.
    Viewer,
    /// Reads, jobs and the daily controls (pause, resume, lock, retry, acknowledge).
    Operator,
    /// Everything.
    Admin,
}

impl From<Role> for RoleName {
    fn from(role: Role) -> RoleName {
        match role {
            Role::Viewer => RoleName::Viewer,
            Role::Operator => RoleName::Operator,
            Role::Admin => RoleName::Admin,
        }
    }
}

/// The caller.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"name": "control-room", "role": "viewer"}))]
pub struct WhoAmI {
    /// The key's name from the configuration (`anonymous` without keys).
    pub name: String,
    /// What it may do; each role includes the ones before it.
    pub role: RoleName,
}

/// Who the presented key is and what it may do (any valid key).
#[utoipa::path(get, path = "/whoami", tag = "operations",
    responses(
        (status = 200, description = "The key's name and role", body = WhoAmI),
        (status = 401, description = "No key, or an unknown key", body = ErrorBody),
    ))]
async fn whoami(who: Option<Extension<Principal>>) -> Json<WhoAmI> {
    Json(match who {
        Some(Extension(p)) => WhoAmI { name: p.name, role: p.role.into() },
        None => WhoAmI { name: "anonymous".to_owned(), role: RoleName::Admin },
    })
}
