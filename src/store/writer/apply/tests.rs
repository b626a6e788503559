use super::*;
use crate::domain::JobSpec;

fn submit(references: std::ops::Range<u32>) -> Command {
    let jobs = references
        .map(|n| NewJob {
            spec: JobSpec::Travel { to: Location { aisle: 1, row: 1, bay: 2, level: 3, position: 1 } },
            reference: Some(format!("r{n}")),
            priority: Default::default(),
            barcode: None,
            device: None,
            serves: None,
        })
        .collect();
    Command::Submit { jobs, reply: tokio::sync::oneshot::channel().0 }
}

const START: Next = Next { job: 1, seq: 1, audit: 1, alarm: 1 };

#[test]
fn the_next_group_gets_the_map_of_jobs_emptied_and_still_allocated() {
    let mut spare = Spare::default();
    let first = submit(0..100);
    let mut group = Group::new(Loaded::default(), START, 0, None, &[&first], &mut spare);
    assert!(matches!(group.command(&first), Answer::Submitted(Ok(o)) if o.len() == 100));
    assert_eq!(group.jobs.len(), 100);
    let next = group.next;
    group.recycle(&mut spare);
    assert!(spare.jobs.is_empty());
    let room = spare.jobs.capacity();
    assert!(room >= 100);

    let second = submit(100..110);
    let mut group = Group::new(Loaded::default(), next, 0, None, &[&second], &mut spare);
    assert_eq!(group.jobs.capacity(), room, "the map was allocated anew");
    assert!(matches!(group.command(&second), Answer::Submitted(Ok(o)) if o.len() == 10));
    // Only the second group's jobs, numbered after the first's: none of the first's is left.
    let mut ids: Vec<i64> = group.jobs.keys().copied().collect();
    ids.sort();
    assert_eq!(ids, (101..=110).collect::<Vec<_>>());
    // A reference of the first group is not seen as one this group created.
    assert!(group.seen("r5").is_none());
}

#[test]
fn a_map_with_room_for_more_than_the_most_is_let_go() {
    let mut spare = Spare::default();
    let mut group = Group::new(Loaded::default(), START, 0, None, &[], &mut spare);
    group.jobs.reserve(Spare::MOST + 1);
    group.recycle(&mut spare);
    assert_eq!(spare.jobs.capacity(), 0);
}
