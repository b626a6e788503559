//! Job intake: turns what a WMS posts into validated [`NewJob`]s.
//!
//! A request is a flat object (`kind` plus the fields that kind needs); each kind takes
//! exactly its own fields, so a `store` with a `from` is an error, not a silently ignored
//! field. Locations are checked against the site layout, and a named device must exist.

use std::collections::{BTreeMap, BTreeSet};

use serde::Deserialize;
use utoipa::ToSchema;

use crate::domain::{
    Barcode, Class, Invalid, JobKind, JobSpec, Layout, LightColor, Location, Priority, Zone,
};
use crate::store::jobs::NewJob;

/// Longest accepted WMS reference.
pub const MAX_REFERENCE_LEN: usize = 100;

/// Most jobs in one batch.
pub const MAX_BATCH: usize = 1000;

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
        Ok(NewJob { spec, reference: req.reference, priority, barcode, device, serves: None, terms: Default::default() })
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
    let printable = r.chars().all(|c| !c.is_control());
    if r.trim().is_empty() || r.chars().count() > MAX_REFERENCE_LEN || !printable {
        return Err(Invalid(format!(
            "reference must be 1..={MAX_REFERENCE_LEN} printable characters, not blank"
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
