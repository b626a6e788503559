//! A submission's terms checked against what is stored, in the group's transaction: the
//! jobs `after` names exist and wait for no cycle, and each sequence member fits its
//! sequence (position free and not after the last, sequence neither complete nor
//! cancelled, one station). And the
//! record that completes or cancels a sequence.
//!
//! The writer is the one place these can be checked without a race: two requests for one
//! position, or a member and the sequence's completion, are applied one after the other.

use std::collections::{BTreeMap, HashMap, HashSet};

use super::Group;
use crate::domain::{Job, Who};
use crate::store::jobs::NewJob;
use crate::store::sequences::{Row, Stored, StoredMember};
use crate::store::writer::WriteError;

/// What a submission's terms change, once they are all found good.
pub(super) struct Staged {
    sequences: BTreeMap<String, Stored>,
}

impl Group {
    /// Checks the terms of a submission's new jobs (`created`, with their requests' index in
    /// `jobs`): nothing is changed until every one is good.
    pub(super) fn check_terms(
        &self,
        jobs: &[NewJob],
        created: &[(usize, &Job)],
    ) -> Result<Staged, WriteError> {
        self.check_after(jobs, created)?;
        let mut staged: BTreeMap<String, Stored> = BTreeMap::new();
        for &(i, job) in created {
            let Some(member) = &jobs[i].terms.sequence else { continue };
            let (name, position) = (&member.name, member.position);
            let seq = match staged.get_mut(name) {
                Some(s) => s,
                None => {
                    let s = self.sequences.get(name).cloned().unwrap_or_else(|| Stored {
                        row: Row {
                            name: name.clone(),
                            station: jobs[i].terms.station.map(i64::from),
                            last: None,
                            completed_at: None,
                            cancelled_at: None,
                            created_at: self.now,
                            updated_at: self.now,
                        },
                        members: BTreeMap::new(),
                    });
                    staged.entry(name.clone()).or_insert(s)
                }
            };
            let refuse = |why: String| Err(WriteError::Sequence(format!("sequence {name:?}: {why}")));
            if seq.row.cancelled_at.is_some() {
                return refuse("it was cancelled: no member may join it".into());
            }
            if seq.row.completed_at.is_some() {
                return refuse("it is complete: no member may join it".into());
            }
            if let Some(last) = seq.row.last.filter(|&l| i64::from(position) > l) {
                return refuse(format!("its last position is {last}: position {position} cannot join it"));
            }
            if let Some(station) = jobs[i].terms.station.map(i64::from)
                && seq.row.station != Some(station)
            {
                let goes = seq.row.station.map_or("no station".to_owned(), |s| format!("station {s}"));
                return refuse(format!("it goes to {goes}, this member names station {station}"));
            }
            if let Some(taken) = seq.members.get(&position) {
                return refuse(format!("position {position} is taken by job {}", taken.job));
            }
            if jobs[i].terms.last {
                if let Some((&after, _)) = seq.members.range(position..).next() {
                    return refuse(format!(
                        "position {position} cannot be the last: position {after} is posted"
                    ));
                }
                if let Some(last) = seq.row.last.filter(|&l| l != i64::from(position)) {
                    return refuse(format!("its last position is {last}, not {position}"));
                }
                seq.row.last = Some(i64::from(position));
            }
            let m = StoredMember {
                position,
                job: job.id,
                reference: job.reference.clone(),
                state: Some(job.state),
                updated_at: Some(self.now),
                aisle: job.spec().and_then(|s| s.locations().first().map(|l| l.aisle)),
            };
            seq.members.insert(position, m);
            seq.row.updated_at = self.now;
        }
        Ok(Staged { sequences: staged })
    }

    /// Every reference in `after` names a job stored, created earlier in the group, or in
    /// this submission, and the submission's jobs do not wait for each other in a circle.
    fn check_after(&self, jobs: &[NewJob], created: &[(usize, &Job)]) -> Result<(), WriteError> {
        let here: HashMap<&str, usize> =
            jobs.iter().enumerate().filter_map(|(i, j)| Some((j.reference.as_deref()?, i))).collect();
        for &(i, job) in created {
            for r in &jobs[i].terms.after {
                let known = here.contains_key(r.as_str())
                    || self.after.contains_key(r)
                    || self.created_refs.contains_key(r);
                if !known {
                    return Err(WriteError::UnknownDependency(format!(
                        "{}: `after` names {r:?}, which is no job's reference",
                        named(job)
                    )));
                }
            }
        }
        // A cycle can only run through this submission: stored jobs were accepted before
        // any of its references existed.
        let mut done: HashSet<usize> = HashSet::new();
        for &(start, _) in created {
            let mut path: Vec<usize> = Vec::new();
            if let Some(cycle) = cycle_from(start, jobs, &here, &mut path, &mut done) {
                let names: Vec<String> = cycle
                    .iter()
                    .map(|&i| format!("{:?}", jobs[i].reference.as_deref().unwrap_or("?")))
                    .collect();
                return Err(WriteError::DependencyCycle(format!(
                    "jobs wait for each other in a circle: {}",
                    names.join(" -> ")
                )));
            }
        }
        Ok(())
    }

    /// Takes in what a good submission's terms change.
    pub(super) fn stage(&mut self, staged: Staged) {
        for (name, seq) in staged.sequences {
            let stored = self.sequences.get(&name);
            let new: Vec<(String, u32, i64)> = seq
                .members
                .values()
                .filter(|m| !stored.is_some_and(|s| s.members.contains_key(&m.position)))
                .map(|m| (name.clone(), m.position, m.job))
                .collect();
            self.new_members.extend(new);
            self.sequences.insert(name.clone(), seq);
            self.sequence_changed(&name);
        }
    }

    /// Completes the sequence `name` (and with `cancel` cancels it), as `who` asked.
    pub(super) fn sequence(&mut self, name: &str, cancel: bool, who: Option<&Who>) -> Result<(), WriteError> {
        let now = self.now;
        let Some(seq) = self.sequences.get_mut(name) else {
            return Err(WriteError::Sequence(format!("sequence {name:?} does not exist")));
        };
        let mut changed = false;
        if seq.row.completed_at.is_none() {
            seq.row.completed_at = Some(now);
            if seq.row.last.is_none() {
                seq.row.last = Some(seq.members.keys().next_back().map_or(0, |&p| i64::from(p)));
            }
            changed = true;
        }
        if cancel && seq.row.cancelled_at.is_none() {
            seq.row.cancelled_at = Some(now);
            changed = true;
        }
        if changed {
            seq.row.updated_at = now;
            self.sequence_changed(name);
            let by = who.map_or("rackd", |w| w.name.as_str());
            let action = if cancel { "cancel" } else { "complete" };
            self.audit(by, who.and_then(|w| w.client), action, &format!("sequence:{name}"), None);
        }
        Ok(())
    }

    /// Notes that sequence `name` changed: its row is written, told in a `sequence.updated`
    /// event and handed to the dispatcher after the commit.
    fn sequence_changed(&mut self, name: &str) {
        if let Some(seq) = self.sequences.get(name) {
            let row = seq.row.clone();
            self.event("sequence.updated", &row);
            self.sequences_changed.insert(name.to_owned());
        }
    }
}

/// A job as an error names it.
fn named(job: &Job) -> String {
    match &job.reference {
        Some(r) => format!("job {r:?}"),
        None => "a job".into(),
    }
}

/// A circle of `after` among a submission's jobs reached from `at`, as the indexes along it.
fn cycle_from(
    at: usize,
    jobs: &[NewJob],
    here: &HashMap<&str, usize>,
    path: &mut Vec<usize>,
    done: &mut HashSet<usize>,
) -> Option<Vec<usize>> {
    if let Some(from) = path.iter().position(|&i| i == at) {
        let mut cycle = path[from..].to_vec();
        cycle.push(at);
        return Some(cycle);
    }
    if done.contains(&at) {
        return None;
    }
    path.push(at);
    for r in &jobs[at].terms.after {
        if let Some(&next) = here.get(r.as_str())
            && let Some(cycle) = cycle_from(next, jobs, here, path, done)
        {
            return Some(cycle);
        }
    }
    path.pop();
    done.insert(at);
    None
}
