//! What a job asks for: its kind and the fields that kind needs, and no others.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::Location;

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

/// A job's kind with exactly the fields it needs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
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
}

impl JobSpec {
    /// The job's kind.
    pub fn kind(&self) -> JobKind {
        match self {
            Self::Store { .. } => JobKind::Store,
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
