//! A store that leaves the location to rackd (putaway): where the box may go (zones) and
//! how often it is expected to move (a velocity class).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{Invalid, Layout, Location};

/// A part of an aisle: the aisle, and any of row, bay, level and position to narrow it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"aisle": 2, "row": 1}))]
pub struct Zone {
    /// The aisle.
    pub aisle: u16,
    /// Only this row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row: Option<u16>,
    /// Only this bay.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bay: Option<u16>,
    /// Only this level.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level: Option<u16>,
    /// Only this position (depth: 1 near, 2 far).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<u16>,
}

impl Zone {
    /// The whole aisle.
    pub fn aisle(aisle: u16) -> Zone {
        Zone { aisle, row: None, bay: None, level: None, position: None }
    }

    /// Whether `l` lies in the zone.
    pub fn contains(&self, l: Location) -> bool {
        let fits = |want: Option<u16>, have: u16| want.is_none_or(|w| w == have);
        self.aisle == l.aisle
            && fits(self.row, l.row)
            && fits(self.bay, l.bay)
            && fits(self.level, l.level)
            && fits(self.position, l.position)
    }

    /// Checks that the zone is a part of the site `layout` describes: its aisle exists and
    /// each number it names is a storage location's (a zone never names the station, bay 0).
    pub fn check(&self, layout: &Layout) -> Result<(), Invalid> {
        let Some(aisle) = layout.aisles().get(&self.aisle) else {
            return Err(Invalid(format!("zone: aisle {} does not exist", self.aisle)));
        };
        let checks = [
            ("row", self.row, aisle.rows),
            ("bay", self.bay, aisle.bays),
            ("level", self.level, aisle.levels),
            ("position", self.position, aisle.positions),
        ];
        for (name, value, max) in checks {
            if let Some(v) = value.filter(|v| *v < 1 || *v > max) {
                return Err(Invalid(format!(
                    "zone in aisle {}: {name} {v} is outside 1..={max}",
                    self.aisle
                )));
            }
        }
        Ok(())
    }
}

/// A velocity class: how often a box is expected to move.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, ToSchema)]
pub enum Class {
    /// Fast movers: the third of the aisle nearest the station by travel time.
    A,
    /// The middle third.
    B,
    /// Slow movers: the farthest third.
    C,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zone_narrows_by_what_it_names() {
        let l = Location { aisle: 2, row: 1, bay: 5, level: 3, position: 2 };
        assert!(Zone::aisle(2).contains(l));
        assert!(!Zone::aisle(1).contains(l));
        assert!(Zone { row: Some(1), level: Some(3), ..Zone::aisle(2) }.contains(l));
        assert!(!Zone { position: Some(1), ..Zone::aisle(2) }.contains(l));
        let json = serde_json::to_value(Zone { row: Some(1), ..Zone::aisle(2) }).unwrap();
        assert_eq!(json, serde_json::json!({"aisle": 2, "row": 1}));
        assert_eq!(serde_json::to_value(Class::A).unwrap(), "A");
    }
}
