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
            terms: Default::default(),
        })
        .collect();
    Command::Submit { jobs, who: None, reply: tokio::sync::oneshot::channel().0 }
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

fn submit_as(references: std::ops::Range<u32>, name: &str, client: &str) -> Command {
    let Command::Submit { jobs, reply, .. } = submit(references) else { unreachable!() };
    let who = crate::domain::Who { name: name.into(), client: Some(client.parse().unwrap()) };
    Command::Submit { jobs, who: Some(who), reply }
}

#[test]
fn a_groups_submissions_are_audited_once_per_caller() {
    let mut spare = Spare::default();
    let cmds = [
        submit_as(0..1, "wms", "10.0.0.1"),
        submit_as(1..2, "wms", "10.0.0.1"),
        submit_as(2..3, "hmi", "10.0.0.2"),
        submit_as(3..4, "wms", "10.0.0.1"),
        submit(4..5),
    ];
    let refs: Vec<&Command> = cmds.iter().collect();
    let mut group = Group::new(Loaded::default(), START, 0, None, &refs, &mut spare);
    for cmd in &cmds {
        assert!(matches!(group.command(cmd), Answer::Submitted(Ok(_))));
    }
    group.audit_submissions();
    let entries: Vec<(&str, &str, &str, Option<&str>)> = group
        .audit
        .iter()
        .map(|a| (a.by.as_str(), a.client.as_deref().unwrap(), a.target.as_str(), a.reason.as_deref()))
        .collect();
    assert_eq!(
        entries,
        [
            ("wms", "10.0.0.1", "jobs:1-2,4", Some("3 submissions in one commit, 3 new jobs")),
            ("hmi", "10.0.0.2", "job:3", None),
        ],
        "a submission sent without a caller (rackd's own) is not audited"
    );
    assert!(group.out.events.iter().all(|e| e.kind == "job.updated"), "submissions publish no audit event");

    let batch = [submit_as(10..14, "wms", "10.0.0.1")];
    let refs: Vec<&Command> = batch.iter().collect();
    let mut group = Group::new(Loaded::default(), group.next, 0, None, &refs, &mut spare);
    group.command(&batch[0]);
    group.audit_submissions();
    assert_eq!(group.audit[0].target, "jobs:6-9");
    assert_eq!(group.audit[0].reason.as_deref(), Some("a batch of 4 jobs"));
}
