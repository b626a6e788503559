//! Job intake: turns what a WMS posts into validated [`NewJob`]s.
//!
//! A request is a flat object (`kind` plus the fields that kind needs); each kind takes
//! exactly its own fields, so a `store` with a `from` is an error, not a silently ignored
//! field. Locations are checked against the site layout, and a named device must exist.
//! A job's terms (`sequence`, `deadline`, `after`) are checked for form here; whether they
//! fit what is stored (a position free, the jobs `after` names existing, no circle) is the
//! job writer's to check, in the transaction that stores the job (`store::writer::apply`).

use std::collections::{BTreeMap, BTreeSet};

use serde::Deserialize;
use utoipa::ToSchema;

use crate::domain::{
    Barcode, Class, Invalid, JobKind, JobSpec, Layout, LightColor, Location, Member, Priority, Terms, Zone,
};
use crate::store::jobs::NewJob;

/// Longest accepted WMS reference.
pub const MAX_REFERENCE_LEN: usize = 100;

/// Most jobs in one batch.
pub const MAX_BATCH: usize = 1000;

/// The highest position in a sequence.
pub const MAX_POSITION: u32 = 1_000_000;

/// Most references one job's `after` names.
pub const MAX_AFTER: usize = 100;

/// A job as the WMS posts it.
#[derive(Clone, Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"kind": "store", "reference": "WMS-1001", "priority": 10, "barcode": "BOX-0001",
    "to": {"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 1}}))]
pub struct JobRequest {
    /// What the job does; decides which of `from`, `to`, `location`, `color`, `on` are required
    /// (store: to, or `aisle` or `zones` to let rackd choose; retrieve: from; move: from, to;
    /// clear: location; light: location, color, on; travel: to) and that the others are absent.
    pub kind: JobKind,
    /// The WMS's own id for the job (1..=100 printable characters), unique: a repeated POST
    /// with the same reference and body returns the existing job; a different body is a 409.
    pub reference: Option<String>,
    /// 0..=20, lower first; 0 jumps the queue. Default 10.
    #[schema(minimum = 0, maximum = 20, default = 10)]
    pub priority: Option<i64>,
    /// The box's barcode: 1..=20 printable ASCII characters.
    pub barcode: Option<String>,
    /// Source location (retrieve, move).
    pub from: Option<Location>,
    /// Target location (store, move, travel).
    pub to: Option<Location>,
    /// The location (clear, light).
    pub location: Option<Location>,
    /// Which light (light).
    pub color: Option<LightColor>,
    /// Switch it on (true) or off (false) (light).
    pub on: Option<bool>,
    /// Run on this device instead of the one that serves the locations.
    pub device: Option<String>,
    /// A store without `to`: rackd chooses a location of this crane aisle as it dispatches
    /// the job (putaway).
    pub aisle: Option<u16>,
    /// A store without `to`: rackd chooses a location in one of these parts of one crane
    /// aisle (each the aisle and any of row, bay, level, position).
    pub zones: Option<Vec<Zone>>,
    /// A store left to rackd: the box's velocity class (A: the nearest third of the aisle by
    /// the crane's travel time, B the middle, C the farthest).
    pub class: Option<Class>,
    /// A retrieve, move or travel that is a member of a sequence: the members of one sequence
    /// reach their destination in `position` order.
    pub sequence: Option<SequenceRequest>,
    /// When the job should have ended (RFC 3339, e.g. `2026-11-29T14:00:00Z`). A job past
    /// its deadline is not failed: it is told late, and the crane planner runs a job whose
    /// deadline is at risk first.
    #[schema(value_type = Option<String>, format = DateTime)]
    pub deadline: Option<String>,
    /// References of jobs (stored, or in the same batch) that must complete before this one
    /// starts; at most 100.
    pub after: Option<Vec<String>>,
}

/// A job's place in a sequence, as the WMS posts it.
#[derive(Clone, Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"name": "ORD-77", "position": 1, "station": 3}))]
pub struct SequenceRequest {
    /// The sequence's name: 1..=100 printable characters (the WMS's order, say).
    pub name: String,
    /// 1..=1000000: members reach the destination in this order, 1 first.
    #[schema(minimum = 1, maximum = 1000000)]
    pub position: i64,
    /// The station the sequence goes to (a `[[site.stations]]` id), which sets the transit
    /// times rackd releases members across aisles by; named by the first member, repeated
    /// or left out by the others.
    pub station: Option<u16>,
    /// True on the last member: the sequence is then complete, no member may follow.
    #[serde(default)]
    pub last: bool,
}

/// What intake checks requests against.
#[derive(Clone, Debug, Default)]
pub struct Rules {
    /// The site layout.
    pub layout: Layout,
    /// The configured devices and the job kinds each can run.
    pub devices: BTreeMap<String, &'static [JobKind]>,
    /// Which device serves each aisle.
    pub routes: BTreeMap<u16, String>,
    /// The double-deep aisles (`depth = 2`).
    pub deep: BTreeSet<u16>,
    /// The aisles a crane serves: where a store may leave its location to rackd.
    pub crane_aisles: BTreeSet<u16>,
    /// The configured stations (`[[site.stations]]`).
    pub stations: BTreeSet<u16>,
}

impl Rules {
    /// The rules `config` sets: its layout, and which device runs which jobs where.
    pub fn of(config: &crate::config::Config) -> Rules {
        use crate::config::devices::DeviceConfig;
        let devices = &config.devices;
        Rules {
            layout: config.layout(),
            deep: config.site.aisles.iter().filter(|a| a.depth == 2).map(|a| a.aisle).collect(),
            crane_aisles: devices
                .iter()
                .filter(|d| matches!(d, DeviceConfig::Crane(_)))
                .flat_map(|d| d.aisles().iter().copied())
                .collect(),
            devices: devices.iter().map(|d| (d.id().to_owned(), d.kind().job_kinds())).collect(),
            routes: devices.iter().flat_map(|d| d.aisles().iter().map(|&a| (a, d.id().to_owned()))).collect(),
            stations: config.site.stations.iter().map(|s| s.id).collect(),
        }
    }

    /// Validates one request into a job to store.
    pub fn check(&self, req: JobRequest) -> Result<NewJob, Invalid> {
        let kind = req.kind;
        let present = [
            ("from", req.from.is_some()),
            ("to", req.to.is_some()),
            ("location", req.location.is_some()),
            ("color", req.color.is_some()),
            ("on", req.on.is_some()),
        ];
        let putaway = self.putaway(&req)?;
        let wanted = |field: &str| kind.fields().contains(&field) && (putaway.is_none() || field != "to");
        if let Some((field, _)) = present.iter().find(|(f, p)| *p && !wanted(f)) {
            return Err(Invalid(format!("a {} job takes no `{field}`", kind.as_str())));
        }
        if let Some((field, _)) = present.iter().find(|(f, p)| !*p && wanted(f)) {
            return Err(Invalid(format!("a {} job needs `{field}`", kind.as_str())));
        }
        let missing = || Invalid("internal: field checked above".into());
        let spec = match kind {
            JobKind::Store => match putaway {
                Some(spec) => spec,
                None => JobSpec::Store { to: req.to.ok_or_else(missing)? },
            },
            JobKind::Retrieve => JobSpec::Retrieve { from: req.from.ok_or_else(missing)? },
            JobKind::Move => {
                JobSpec::Move { from: req.from.ok_or_else(missing)?, to: req.to.ok_or_else(missing)? }
            }
            JobKind::Clear => JobSpec::Clear { location: req.location.ok_or_else(missing)? },
            JobKind::Light => JobSpec::Light {
                location: req.location.ok_or_else(missing)?,
                color: req.color.ok_or_else(missing)?,
                on: req.on.ok_or_else(missing)?,
            },
            JobKind::Travel => JobSpec::Travel { to: req.to.ok_or_else(missing)? },
        };
        for loc in spec.locations() {
            self.layout.check(&loc)?;
        }
        if let JobSpec::Move { from, to } = spec
            && from == to
        {
            return Err(Invalid(format!("a move needs two different locations, got {from} twice")));
        }
        let priority = req.priority.map(Priority::try_from).transpose()?.unwrap_or_default();
        let barcode = req.barcode.map(Barcode::try_from).transpose()?;
        if let Some(r) = &req.reference {
            check_reference(r)?;
        }
        let device = self.route(&spec, req.device)?;
        let terms = self.terms(kind, req.sequence, req.deadline, req.after)?;
        Ok(NewJob { spec, reference: req.reference, priority, barcode, device, serves: None, terms })
    }

    /// A job's terms: its sequence (retrieve, move, travel only), deadline and the references
    /// it waits for, each checked.
    fn terms(
        &self,
        kind: JobKind,
        sequence: Option<SequenceRequest>,
        deadline: Option<String>,
        after: Option<Vec<String>>,
    ) -> Result<Terms, Invalid> {
        let mut terms = Terms::default();
        if let Some(s) = sequence {
            if !matches!(kind, JobKind::Retrieve | JobKind::Move | JobKind::Travel) {
                return Err(Invalid(format!(
                    "a {} job takes no `sequence`: sequences order retrieve, move and travel jobs",
                    kind.as_str()
                )));
            }
            check_text("sequence.name", &s.name)?;
            let position = u32::try_from(s.position)
                .ok()
                .filter(|p| (1..=MAX_POSITION).contains(p))
                .ok_or_else(|| Invalid(format!("sequence.position must be 1..={MAX_POSITION}")))?;
            if let Some(station) = s.station
                && !self.stations.contains(&station)
            {
                let known: Vec<String> = self.stations.iter().map(u16::to_string).collect();
                return Err(Invalid(format!(
                    "sequence.station {station} is not configured (site.stations: [{}])",
                    known.join(", ")
                )));
            }
            terms.sequence = Some(Member { name: s.name, position });
            (terms.station, terms.last) = (s.station, s.last);
        }
        if let Some(text) = deadline {
            let at = time::OffsetDateTime::parse(&text, &time::format_description::well_known::Rfc3339)
                .map_err(|_| {
                    Invalid(format!("deadline {text:?} is not an RFC 3339 time (e.g. 2026-11-29T14:00:00Z)"))
                })?;
            terms.deadline = Some(crate::domain::time::to_ms(at));
        }
        if let Some(after) = after {
            if after.len() > MAX_AFTER {
                return Err(Invalid(format!("`after` names at most {MAX_AFTER} jobs")));
            }
            for r in &after {
                check_text("after", r)?;
                if !terms.after.contains(r) {
                    terms.after.push(r.clone());
                }
            }
        }
        Ok(terms)
    }

    /// A store left to rackd, from `aisle`, `zones` and `class` (none of which any other
    /// request takes); None when the request names none of them.
    fn putaway(&self, req: &JobRequest) -> Result<Option<JobSpec>, Invalid> {
        let named =
            [("aisle", req.aisle.is_some()), ("zones", req.zones.is_some()), ("class", req.class.is_some())];
        let Some((first, _)) = named.iter().find(|(_, p)| *p) else { return Ok(None) };
        if req.kind != JobKind::Store {
            return Err(Invalid(format!("a {} job takes no `{first}`", req.kind.as_str())));
        }
        if req.to.is_some() {
            return Err(Invalid(format!(
                "a store takes `to`, or `aisle`/`zones` for rackd to choose, not `to` and `{first}`"
            )));
        }
        let mut zones = req.zones.clone().unwrap_or_default();
        match (req.aisle, zones.is_empty()) {
            (Some(aisle), true) => zones.push(Zone::aisle(aisle)),
            (None, true) if req.zones.is_some() => {
                return Err(Invalid("`zones` needs at least one zone".into()));
            }
            (None, true) => {
                return Err(Invalid("`class` needs `aisle` or `zones`: where rackd may choose".into()));
            }
            _ => {}
        }
        let aisle = zones[0].aisle;
        if zones.iter().any(|z| z.aisle != aisle) || req.aisle.is_some_and(|a| a != aisle) {
            return Err(Invalid("every zone must be in the same aisle (one crane chooses)".into()));
        }
        if !self.crane_aisles.contains(&aisle) {
            return Err(Invalid(format!(
                "aisle {aisle} is served by no crane: name the store's location in `to`"
            )));
        }
        for z in &zones {
            z.check(&self.layout)?;
        }
        Ok(Some(JobSpec::Putaway { zones, class: req.class }))
    }

    /// The device a job runs on: the one named, or the one serving its locations' aisle.
    /// With no device that runs jobs (none, or only tags devices) jobs have none and stay
    /// queued. A device that runs no jobs (tags) serves no aisle and refuses any job named
    /// for it.
    fn route(&self, spec: &JobSpec, named: Option<String>) -> Result<Option<String>, Invalid> {
        if named.is_none() && self.devices.values().all(|kinds| kinds.is_empty()) {
            return Ok(None);
        }
        let device = match named {
            Some(d) if self.devices.contains_key(&d) => d,
            Some(d) => {
                let known: Vec<_> = self.devices.keys().map(String::as_str).collect();
                return Err(Invalid(format!(
                    "device {d:?} is not configured (devices: [{}])",
                    known.join(", ")
                )));
            }
            None => {
                let mut aisles = match spec {
                    JobSpec::Putaway { zones, .. } => zones.iter().map(|z| z.aisle).collect(),
                    _ => spec.locations().into_iter().map(|l| l.aisle).collect::<Vec<_>>(),
                };
                aisles.dedup();
                let routed: Vec<_> = aisles.iter().map(|a| self.routes.get(a)).collect();
                match routed.as_slice() {
                    [Some(d)] => (*d).clone(),
                    [Some(a), Some(b)] if a == b => (*a).clone(),
                    _ => {
                        return Err(Invalid(format!(
                            "no single device serves aisle(s) {aisles:?}; name one with `device`"
                        )));
                    }
                }
            }
        };
        let kinds = self.devices.get(&device).copied().unwrap_or(&[]);
        if !kinds.contains(&spec.kind()) {
            return Err(Invalid(format!("device {device:?} cannot run {} jobs", spec.kind().as_str())));
        }
        Ok(Some(device))
    }
}

fn check_reference(r: &str) -> Result<(), Invalid> {
    check_text("reference", r)
}

/// A WMS's name for something (a reference, a sequence): 1..=100 printable characters.
fn check_text(what: &str, r: &str) -> Result<(), Invalid> {
    let printable = r.chars().all(|c| !c.is_control());
    if r.trim().is_empty() || r.chars().count() > MAX_REFERENCE_LEN || !printable {
        return Err(Invalid(format!(
            "{what} must be 1..={MAX_REFERENCE_LEN} printable characters, not blank"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::domain::AisleLayout;

    fn rules() -> Rules {
        let aisle = AisleLayout { rows: 2, bays: 10, levels: 6, positions: 4 };
        Rules { layout: Layout::new(BTreeMap::from([(1, aisle)])), ..Rules::default() }
    }

    fn req(json: serde_json::Value) -> JobRequest {
        serde_json::from_value(json).unwrap()
    }

    const LOC: fn() -> serde_json::Value =
        || serde_json::json!({"aisle":1,"row":1,"bay":1,"level":1,"position":1});

    #[test]
    fn each_kind_takes_its_fields() {
        let ok = rules().check(req(serde_json::json!({"kind": "store", "to": LOC()}))).unwrap();
        assert_eq!(ok.priority, Priority::DEFAULT);
        let err = rules().check(req(serde_json::json!({"kind": "store", "to": LOC(), "from": LOC()})));
        assert!(err.unwrap_err().0.contains("takes no `from`"));
        let err = rules().check(req(serde_json::json!({"kind": "light", "location": LOC(), "color": "red"})));
        assert!(err.unwrap_err().0.contains("needs `on`"));
    }

    #[test]
    fn moves_need_two_places_and_devices_must_exist() {
        let err = rules().check(req(serde_json::json!({"kind": "move", "from": LOC(), "to": LOC()})));
        assert!(err.unwrap_err().0.contains("two different"));
        let err = rules().check(req(serde_json::json!({"kind": "clear", "location": LOC(), "device": "x"})));
        assert!(err.unwrap_err().0.contains("not configured"));
    }

    #[test]
    fn a_tags_device_is_never_routed_jobs() {
        let mut r = rules();
        r.devices.insert("tower1".into(), crate::config::devices::DeviceKind::Tags.job_kinds());
        let queued = r.check(req(serde_json::json!({"kind": "store", "to": LOC()}))).unwrap();
        assert_eq!(queued.device, None, "only a tags device: the job waits for a real one");
        let err = r.check(req(serde_json::json!({"kind": "clear", "location": LOC(), "device": "tower1"})));
        assert!(err.unwrap_err().0.contains("cannot run clear jobs"));
        r.devices.insert("shelf1".into(), crate::config::devices::DeviceKind::Shelf.job_kinds());
        r.routes.insert(1, "shelf1".into());
        let routed = r.check(req(serde_json::json!({"kind": "store", "to": LOC()}))).unwrap();
        assert_eq!(routed.device.as_deref(), Some("shelf1"));
    }

    #[test]
    fn references_are_checked() {
        let long = "r".repeat(101);
        let err = rules().check(req(serde_json::json!({"kind": "store", "to": LOC(), "reference": long})));
        assert!(err.is_err());
        let err = rules().check(req(serde_json::json!({"kind": "store", "to": LOC(), "reference": "  "})));
        assert!(err.is_err());
    }
}
