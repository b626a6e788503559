//! The refusal at intake of a store a WMS names into a far location whose near location
//! holds a box no unfinished job takes away (a double-deep aisle): a 409 `near_occupied`
//! at once beats a job that could only wait for a relocation the WMS did not ask for. A
//! store accepted before the near location filled is still safe: the planner relocates.

use std::collections::BTreeSet;

use super::rack::Rack;
use crate::domain::{JobSpec, Location};
use crate::store::jobs::NewJob;
use crate::store::{Pool, locations};

/// A store refused: its far location is behind a box.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "location {to} is far behind {near}, which holds a box that no job takes away: store elsewhere, or retrieve or move the box at {near} first"
)]
pub struct NearOccupied {
    /// The job's index in the request.
    pub index: usize,
    /// The far location asked for.
    pub to: Location,
    /// The near location in front of it.
    pub near: Location,
}

/// The first of `jobs` that is such a store, if any; `deep` are the double-deep aisles and
/// `taken` tells whether an unfinished job takes the box at a location away (the
/// dispatcher's `Queues::taking_from`).
pub async fn near_occupied(
    pool: &Pool,
    taken: impl Fn(Location) -> bool,
    deep: &BTreeSet<u16>,
    jobs: &[NewJob],
) -> Result<Option<NearOccupied>, sqlx::Error> {
    for (index, job) in jobs.iter().enumerate() {
        let JobSpec::Store { to } = job.spec else { continue };
        if !deep.contains(&to.aisle) || to.position < 2 || to.bay == 0 {
            continue;
        }
        let near = Rack::near_of(to);
        if !locations::get(pool, near).await?.is_some_and(|s| s.occupied) {
            continue;
        }
        let earlier = jobs[..index].iter().any(|j| picks_from(&j.spec, near));
        if !earlier && !taken(near) {
            return Ok(Some(NearOccupied { index, to, near }));
        }
    }
    Ok(None)
}

/// Whether a job takes the box at `l` away.
pub fn picks_from(spec: &JobSpec, l: Location) -> bool {
    matches!(*spec, JobSpec::Retrieve { from } | JobSpec::Move { from, .. } if from == l)
}
