//! What a job asks for (its kind and the fields that kind needs, and no others), and the job
//! as rackd keeps it: [`NewJob`] once validated, [`Job`] once accepted.

use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::time::from_ms;
use super::{Barcode, Class, Failure, JobState, Location, Priority, Zone};

/// The kinds of job rackd runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JobKind {
    /// Put a box into a location.
    Store,
    /// Take a box out of a location (to the station).
    Retrieve,
    /// Move a box from one location to another.
    Move,
    /// Clear a location.
    Clear,
    /// Switch a location's red or green light on or off.
    Light,
    /// Send a crane to a position without transfer.
    Travel,
}

impl JobKind {
    /// Every kind, in documentation order.
    pub const ALL: [JobKind; 6] =
        [Self::Store, Self::Retrieve, Self::Move, Self::Clear, Self::Light, Self::Travel];

    /// The kind's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Store => "store",
            Self::Retrieve => "retrieve",
            Self::Move => "move",
            Self::Clear => "clear",
            Self::Light => "light",
            Self::Travel => "travel",
        }
    }

    /// Parses a kind from its API name.
    pub fn parse(text: &str) -> Option<JobKind> {
        Self::ALL.into_iter().find(|k| k.as_str() == text)
    }

    /// The location fields this kind takes, as the API names them.
    pub fn fields(self) -> &'static [&'static str] {
        match self {
            Self::Store | Self::Travel => &["to"],
            Self::Retrieve => &["from"],
            Self::Move => &["from", "to"],
            Self::Clear => &["location"],
            Self::Light => &["location", "color", "on"],
        }
    }
}

/// The colour of a location light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum LightColor {
    /// The red light.
    Red,
    /// The green light.
    Green,
}

/// A job's kind with exactly the fields it needs. Stored as JSON (with keys of the store's
/// own beside it, see `store::jobs`), never read from a request: [`crate::service::intake`]
/// checks requests field by field.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum JobSpec {
    /// Put a box into `to`.
    Store {
        /// Where the box goes.
        to: Location,
    },
    /// Take the box at `from` out of the store.
    Retrieve {
        /// Where the box is.
        from: Location,
    },
    /// Move the box at `from` to `to`.
    Move {
        /// Where the box is.
        from: Location,
        /// Where it goes.
        to: Location,
    },
    /// Clear `location`.
    Clear {
        /// The location to clear.
        location: Location,
    },
    /// Switch a light of `location`.
    Light {
        /// The location whose light it is.
        location: Location,
        /// Which light.
        color: LightColor,
        /// On or off.
        on: bool,
    },
    /// Send a crane to `to` without transfer.
    Travel {
        /// Where the crane goes.
        to: Location,
    },
    /// A store whose location rackd chooses when it dispatches it (putaway); once chosen,
    /// the job is a plain [`JobSpec::Store`]. Its kind is `store`.
    Putaway {
        /// Where the box may go: any location in one of these.
        zones: Vec<Zone>,
        /// The box's velocity class, if the WMS gave one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        class: Option<Class>,
    },
}

impl JobSpec {
    /// The job's kind.
    pub fn kind(&self) -> JobKind {
        match self {
            Self::Store { .. } | Self::Putaway { .. } => JobKind::Store,
            Self::Retrieve { .. } => JobKind::Retrieve,
            Self::Move { .. } => JobKind::Move,
            Self::Clear { .. } => JobKind::Clear,
            Self::Light { .. } => JobKind::Light,
            Self::Travel { .. } => JobKind::Travel,
        }
    }

    /// The locations the job touches, source first.
    pub fn locations(&self) -> Vec<Location> {
        match *self {
            Self::Store { to } | Self::Travel { to } => vec![to],
            Self::Retrieve { from } => vec![from],
            Self::Move { from, to } => vec![from, to],
            Self::Clear { location } | Self::Light { location, .. } => vec![location],
            Self::Putaway { .. } => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_round_trip_their_names() {
        for kind in JobKind::ALL {
            assert_eq!(JobKind::parse(kind.as_str()), Some(kind));
        }
        assert_eq!(JobKind::parse("STORE"), None);
    }

    #[test]
    fn spec_serialises_with_its_kind() {
        let loc = Location { aisle: 1, row: 1, bay: 1, level: 1, position: 1 };
        let spec = JobSpec::Light { location: loc, color: LightColor::Green, on: true };
        let json = serde_json::to_value(&spec).unwrap();
        assert_eq!(json["kind"], "light");
        assert_eq!(json["color"], "green");
        assert_eq!(serde_json::from_value::<JobSpec>(json).unwrap(), spec);
        assert_eq!(spec.locations(), vec![loc]);
    }
}

/// A job as the API shows it.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({
    "id": 1, "reference": "WMS-1001", "kind": "store", "priority": 10, "barcode": "BOX-0001",
    "to": {"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 1}, "device": "shelf1", "serves": null,
    "state": "queued", "forced": false, "failure": null, "attempt": 1,
    "waiting": {"reason": "slots_busy", "text": "every slot of shelf1 is busy with other jobs", "device": "shelf1",
        "code": null, "job": null, "by": null},
    "sequence": null, "deadline": null, "late_by_s": null, "after": [],
    "created_at": "2026-11-21T08:00:00.000Z", "updated_at": "2026-11-21T08:00:00.000Z"}))]
pub struct Job {
    /// rackd's id for the job.
    pub id: i64,
    /// The WMS's reference, unique; the idempotency key.
    pub reference: Option<String>,
    /// What the job does.
    pub kind: JobKind,
    /// 0..=20, lower first.
    pub priority: u8,
    /// The box's barcode, if given.
    pub barcode: Option<String>,
    /// Source location (`retrieve`, `move`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<Location>,
    /// Target location (`store`, `move`, `travel`); for a store left to rackd, absent
    /// until rackd chooses it as it dispatches the job.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub to: Option<Location>,
    /// Where a store left to rackd may go (putaway).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zones: Option<Vec<Zone>>,
    /// The velocity class of a store left to rackd, if given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub class: Option<Class>,
    /// The location (`clear`, `light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub location: Option<Location>,
    /// The light (`light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color: Option<LightColor>,
    /// On or off (`light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub on: Option<bool>,
    /// The device that runs the job, once known.
    pub device: Option<String>,
    /// The job this one clears the way for: a relocation rackd made (a `move` of the box in
    /// front of a far location) names the job it serves; null for every job a WMS posts.
    pub serves: Option<i64>,
    /// Where the job is in its life.
    pub state: JobState,
    /// Completed by force on the device (crane forced completion).
    pub forced: bool,
    /// Why the job failed, when it did.
    pub failure: Option<Failure>,
    /// Which attempt this is: 1, and one more each time an operator retries the failed job.
    pub attempt: u32,
    /// Why a queued job is not handed out now (its device offline, paused or in alarm, an
    /// aisle paused, a location locked, an older job on the same location, every slot busy,
    /// no device, an earlier member of its sequence, a job it depends on); null while the
    /// job moves (running, ended, or about to be handed out).
    pub waiting: Option<super::Waiting>,
    /// The sequence the job is a member of, and its place in it (retrieve, move, travel).
    pub sequence: Option<Member>,
    /// When the job should have ended, if the WMS said.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub deadline: Option<OffsetDateTime>,
    /// Whole seconds the job is past its deadline: now for an unfinished job, when it ended
    /// for an ended one; null when it is not late or has no deadline.
    pub late_by_s: Option<i64>,
    /// The references of the jobs that must complete before this one starts.
    pub after: Vec<String>,
    /// When rackd accepted the job.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub created_at: OffsetDateTime,
    /// When the job last changed.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub updated_at: OffsetDateTime,
}

impl Job {
    /// Whole seconds the job is past its deadline at `now_ms` (when it ended, for an ended
    /// job), rounded up; None when it has no deadline or is not late.
    pub fn late_at(&self, now_ms: i64) -> Option<i64> {
        let deadline = super::time::to_ms(self.deadline?);
        let end = if self.state.is_terminal() { super::time::to_ms(self.updated_at) } else { now_ms };
        let late = end - deadline;
        (late > 0).then(|| (late + 999) / 1000)
    }

    /// The job's kind-specific fields.
    pub fn spec(&self) -> Option<JobSpec> {
        Some(match self.kind {
            JobKind::Store => match (self.to, &self.zones) {
                (Some(to), _) => JobSpec::Store { to },
                (None, zones) => JobSpec::Putaway { zones: zones.clone()?, class: self.class },
            },
            JobKind::Retrieve => JobSpec::Retrieve { from: self.from? },
            JobKind::Move => JobSpec::Move { from: self.from?, to: self.to? },
            JobKind::Clear => JobSpec::Clear { location: self.location? },
            JobKind::Light => JobSpec::Light { location: self.location?, color: self.color?, on: self.on? },
            JobKind::Travel => JobSpec::Travel { to: self.to? },
        })
    }
}

/// A member's place in its sequence: the jobs of one sequence reach their destination in
/// `position` order (see `service::dispatch::gate`).
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({"name": "ORD-77", "position": 1}))]
pub struct Member {
    /// The sequence's name (the WMS's, e.g. its order number).
    pub name: String,
    /// 1, 2, 3...: the order in which members reach the destination.
    pub position: u32,
}

/// What a job asks of its place among other jobs: its sequence, its deadline, the jobs it
/// waits for. All empty for a plain job.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Terms {
    /// The sequence it joins, and where.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sequence: Option<Member>,
    /// The sequence's station (a `[[site.stations]]` id), if the request named it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub station: Option<u16>,
    /// This member is the sequence's last: the sequence is complete.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub last: bool,
    /// When it should have ended (Unix ms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deadline: Option<i64>,
    /// The references of the jobs it waits for.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub after: Vec<String>,
}

impl Terms {
    /// Whether the job asks nothing of its place (the common case, kept cheap).
    pub fn is_plain(&self) -> bool {
        self.sequence.is_none() && self.deadline.is_none() && self.after.is_empty()
    }
}

/// A job to be stored, already validated.
#[derive(Clone, Debug, PartialEq)]
pub struct NewJob {
    /// What it does.
    pub spec: JobSpec,
    /// The WMS's reference, if any.
    pub reference: Option<String>,
    /// Its priority.
    pub priority: Priority,
    /// The box's barcode, if any.
    pub barcode: Option<Barcode>,
    /// The device named in the request, if any.
    pub device: Option<String>,
    /// The job this one clears the way for (a relocation rackd made), if any.
    pub serves: Option<i64>,
    /// Its sequence, deadline and dependencies.
    pub terms: Terms,
}

impl NewJob {
    /// The canonical form of the request, compared on a repeated POST with the same reference.
    /// A plain job's is what it was before terms existed (stored requests compare equal).
    pub fn canonical(&self) -> String {
        #[derive(Serialize)]
        struct Canonical<'a> {
            spec: &'a JobSpec,
            reference: &'a Option<String>,
            priority: Priority,
            barcode: &'a Option<Barcode>,
            device: &'a Option<String>,
            #[serde(skip_serializing_if = "Option::is_none")]
            terms: Option<&'a Terms>,
        }
        let c = Canonical {
            spec: &self.spec,
            reference: &self.reference,
            priority: self.priority,
            barcode: &self.barcode,
            device: &self.device,
            terms: (!self.terms.is_plain()).then_some(&self.terms),
        };
        serde_json::to_string(&c).unwrap_or_default()
    }

    /// The job as it is stored on acceptance.
    pub fn accepted(&self, id: i64, now_ms: i64) -> Job {
        let at = from_ms(now_ms);
        let mut job = Job {
            id,
            reference: self.reference.clone(),
            kind: self.spec.kind(),
            priority: self.priority.get(),
            barcode: self.barcode.as_ref().map(|b| b.as_str().to_owned()),
            from: None,
            to: None,
            zones: None,
            class: None,
            location: None,
            color: None,
            on: None,
            device: self.device.clone(),
            serves: self.serves,
            state: JobState::Queued,
            forced: false,
            failure: None,
            attempt: 1,
            waiting: None,
            sequence: self.terms.sequence.clone(),
            deadline: self.terms.deadline.map(from_ms),
            late_by_s: None,
            after: self.terms.after.clone(),
            created_at: at,
            updated_at: at,
        };
        match self.spec.clone() {
            JobSpec::Store { to } | JobSpec::Travel { to } => job.to = Some(to),
            JobSpec::Putaway { zones, class } => (job.zones, job.class) = (Some(zones), class),
            JobSpec::Retrieve { from } => job.from = Some(from),
            JobSpec::Move { from, to } => (job.from, job.to) = (Some(from), Some(to)),
            JobSpec::Clear { location } => job.location = Some(location),
            JobSpec::Light { location, color, on } => {
                (job.location, job.color, job.on) = (Some(location), Some(color), Some(on))
            }
        }
        job
    }
}
