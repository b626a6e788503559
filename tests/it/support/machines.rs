//! What a test that drives the simulated shelf PLC (aisle 1) and crane (aisle 2) checks at
//! its end, whatever it did to rackd meanwhile.

use rackd::sim::crane::CraneSim;
use rackd::sim::shelf::ShelfSim;
use rackd::wire::task_id_for;

/// Each job of `posted` (its id and aisle) reached its machine exactly once, and neither
/// machine saw a breach of its interface.
pub fn each_task_once_and_no_breach(shelf: &ShelfSim, crane: &CraneSim, posted: &[(i64, u16)]) {
    for (id, aisle) in posted {
        let task = task_id_for(*id);
        let received = if *aisle == 1 { shelf.received(task) } else { crane.received(task) };
        assert_eq!(received, 1, "job {id} (aisle {aisle}, task {task}) reached its machine {received} times");
    }
    assert_eq!(shelf.violations(), 0, "the shelf PLC saw writes into busy slots");
    assert_eq!(crane.violations(), 0, "the crane saw breaches: {:#?}", crane.violation_log());
    assert_eq!(crane.refused(), 0, "tasks handed to a busy crane");
}

/// Each of the `jobs` jobs of the PostgreSQL store `db` has one ending in its history,
/// `completed`, and none other (no `failed`, no `cancelled`, no second `completed`).
pub async fn one_completed_ending_each(db: &sqlx::PgPool, jobs: usize) {
    let ends: Vec<(i64, String, i64)> = sqlx::query_as(
        "SELECT job_id, state, COUNT(*) FROM job_history WHERE state IN ('completed', 'failed', 'cancelled') \
         GROUP BY job_id, state ORDER BY job_id",
    )
    .fetch_all(db)
    .await
    .unwrap();
    let odd: Vec<_> = ends.iter().filter(|(_, state, n)| state != "completed" || *n != 1).collect();
    assert!(odd.is_empty(), "job endings other than one `completed`: {odd:?}");
    assert_eq!(ends.len(), jobs, "every job has its `completed` entry");
}
