//! The crane planner: what an idle crane does next, in the service layer beside the
//! dispatcher, which asks it on the crane's behalf ([`CranePlanner::decide`]).
//!
//! - **Double-deep without business alarms** ([`decide::check`]): in an aisle with
//!   `depth = 2` rackd never sends a task the rack makes impossible. A pick or a put far
//!   behind a box gets a relocation first: a `move` of the near box to a place chosen by the
//!   putaway rules ([`putaway`]), made by rackd, naming the job it `serves`, committed before
//!   it is handed over; the job it serves waits behind it. A put into a box fails at once,
//!   nothing sent. A store into a far location whose near location holds a box is refused
//!   at intake (409 `near_occupied`) when the WMS names it ([`refusal`]).
//! - **Sequencing** ([`decide::decide`]): `planner = "travel"` (the default) takes, among
//!   the jobs of the best priority, the one the crane reaches with the least empty travel
//!   (dual command cycles), with aging; `"fifo"` keeps priority then age.
//! - **Deadlines** (`travel` only, within the best priority): the travel choice stands
//!   while every job with a deadline can still end by it less `deadline_margin_s`, run
//!   earliest deadline first after it, each at its cycle as the motion model estimates it
//!   (no hand-over, no station waits, no jobs yet to come); otherwise the earliest deadline
//!   goes first, before a starved job. With slack, deadlines cost no travel. "Now" is the
//!   clock the writer stamps with, read here and passed to the pure decision.
//!
//! The rack it reads is rackd's location model (occupancy and reservations), read afresh
//! for each decision: a crane decides once a cycle, so a read of its aisles is cheap next
//! to the minute a cycle takes, and nothing can go stale. An idle crane asks at every poll,
//! though: after a decision to wait, it is not made again (nor the rack read) until the job
//! writer has committed something since ([`CranePlanner::unchanged_since_wait`]), since
//! every change a decision depends on (a job, a location, a pause or a lock) is a commit.
//! Where the crane stands is where its last task was to end (rackd's own record, not
//! D220/D221, whose units a site's program decides).

pub mod decide;
pub mod putaway;
pub mod rack;
pub mod refusal;

#[cfg(test)]
mod decide_tests;

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use crate::config::devices::CraneConfig;
use crate::domain::{Job, time};
use crate::store::{Pool, locations};
use decide::Memory;
pub use decide::{Decision, Plan, Wait};
use rack::Rack;

/// One crane's planner.
pub struct CranePlanner {
    plan: Plan,
    aisles: Vec<u16>,
    deep: BTreeSet<u16>,
    memory: Mutex<Memory>,
    pool: Pool,
    /// Commits of the job writer so far (bumped by its publish hook).
    commits: Arc<AtomicU64>,
    /// The commit count at the last decision to wait.
    waited_at: Mutex<Option<u64>>,
}

impl CranePlanner {
    /// The planner of `crane`; `deep` are the site's double-deep aisles; `commits` counts
    /// the job writer's commits.
    pub fn new(
        crane: &CraneConfig,
        deep: &BTreeSet<u16>,
        pool: Pool,
        commits: Arc<AtomicU64>,
    ) -> CranePlanner {
        let plan = Plan {
            strategy: crane.planner,
            motion: crane.motion,
            inbound: crane.inbound_station,
            outbound: crane.outbound_station,
            max_overtaken: crane.max_overtaken,
            deadline_margin_s: crane.deadline_margin_s,
        };
        let deep = deep.iter().copied().filter(|a| crane.aisles.contains(a)).collect();
        let memory = Mutex::default();
        CranePlanner {
            plan,
            aisles: crane.aisles.clone(),
            deep,
            memory,
            pool,
            commits,
            waited_at: Mutex::default(),
        }
    }

    /// The writer's commit count now, to note with a decision.
    pub fn commits(&self) -> u64 {
        self.commits.load(Ordering::Acquire)
    }

    /// Notes a decision to wait, made on what stood at commit count `at`.
    pub fn waited(&self, at: u64) {
        *self.waited_at.lock().unwrap_or_else(|p| p.into_inner()) = Some(at);
    }

    /// Whether the last decision was to wait and nothing was committed since.
    pub fn unchanged_since_wait(&self) -> bool {
        *self.waited_at.lock().unwrap_or_else(|p| p.into_inner()) == Some(self.commits())
    }

    /// The crane's aisles as the location model has them now.
    pub async fn rack(&self) -> Result<Rack, sqlx::Error> {
        let mut states = Vec::new();
        for &aisle in &self.aisles {
            states.extend(locations::list(&self.pool, Some(aisle)).await?);
        }
        Ok(Rack::new(&states, &self.deep))
    }

    /// What the idle crane does next, of `candidates` (the order rules' eligible jobs,
    /// best first) given every unfinished job of the crane and the rack; deadlines are
    /// weighed against now on the clock the writer stamps with ([`time::now_ms`]).
    pub fn decide(&self, candidates: &[&Job], unfinished: &[&Job], rack: &Rack) -> Decision {
        let now_ms = time::now_ms();
        let mut memory = self.memory.lock().unwrap_or_else(|p| p.into_inner());
        decide::decide(&self.plan, &mut memory, candidates, unfinished, rack, now_ms)
    }

    /// Why the last decision left `job` waiting, if it did.
    pub fn wait_of(&self, job: i64) -> Option<Wait> {
        self.memory.lock().unwrap_or_else(|p| p.into_inner()).waits.get(&job).copied()
    }
}
