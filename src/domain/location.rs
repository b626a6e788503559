//! Locations in the store and the site layout they are checked against.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::Invalid;

/// A place in the store. All numbers count from 1, except `bay` 0, which is the aisle's
/// station (pick-and-drop point). `row` 1 is A (left), 2 is B (right); `position` is the
/// box position along a shelf level (shelf PLC) or the depth, 1 near / 2 far (crane).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 1}))]
pub struct Location {
    /// Aisle, from 1.
    pub aisle: u16,
    /// Row: 1 = A (left), 2 = B (right).
    pub row: u16,
    /// Bay (shelf) along the aisle, from 1; 0 is the aisle's station.
    pub bay: u16,
    /// Level, bottom-up from 1.
    pub level: u16,
    /// Box position along the level, or depth (1 near, 2 far), from 1.
    pub position: u16,
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}-{}-{}-{}-{}", self.aisle, self.row, self.bay, self.level, self.position)
    }
}

/// The size of one aisle.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AisleLayout {
    /// Rows in the aisle (1 or 2).
    pub rows: u16,
    /// Bays along the aisle.
    pub bays: u16,
    /// Levels per bay.
    pub levels: u16,
    /// Box positions (or depths) per level.
    pub positions: u16,
}

/// The site's layout: which locations exist. Every location in a request is checked here.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    aisles: BTreeMap<u16, AisleLayout>,
}

impl Layout {
    /// A layout from its aisles, keyed by aisle number.
    pub fn new(aisles: BTreeMap<u16, AisleLayout>) -> Self {
        Layout { aisles }
    }

    /// The aisles, by number.
    pub fn aisles(&self) -> &BTreeMap<u16, AisleLayout> {
        &self.aisles
    }

    /// Checks that `loc` exists on this site. Bay 0 (the station) exists in every aisle.
    pub fn check(&self, loc: &Location) -> Result<(), Invalid> {
        let Some(aisle) = self.aisles.get(&loc.aisle) else {
            let known: Vec<_> = self.aisles.keys().map(|a| a.to_string()).collect();
            return Err(Invalid(format!(
                "location {loc}: aisle {} does not exist (aisles: {})",
                loc.aisle,
                known.join(", ")
            )));
        };
        let checks = [
            ("row", loc.row, 1, aisle.rows),
            ("bay", loc.bay, 0, aisle.bays),
            ("level", loc.level, 1, aisle.levels),
            ("position", loc.position, 1, aisle.positions),
        ];
        for (name, value, min, max) in checks {
            if value < min || value > max {
                return Err(Invalid(format!(
                    "location {loc}: {name} {value} is outside {min}..={max} in aisle {}",
                    loc.aisle
                )));
            }
        }
        Ok(())
    }

    /// Every storage location of the site (stations excluded), in order.
    pub fn locations(&self) -> impl Iterator<Item = Location> + '_ {
        self.aisles.iter().flat_map(|(&aisle, a)| {
            (1..=a.rows).flat_map(move |row| {
                (1..=a.bays).flat_map(move |bay| {
                    (1..=a.levels).flat_map(move |level| {
                        (1..=a.positions).map(move |position| Location { aisle, row, bay, level, position })
                    })
                })
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> Layout {
        Layout::new(BTreeMap::from([(1, AisleLayout { rows: 2, bays: 10, levels: 6, positions: 4 })]))
    }

    fn loc(aisle: u16, row: u16, bay: u16, level: u16, position: u16) -> Location {
        Location { aisle, row, bay, level, position }
    }

    #[test]
    fn accepts_inside_and_station() {
        assert!(layout().check(&loc(1, 2, 10, 6, 4)).is_ok());
        assert!(layout().check(&loc(1, 1, 0, 1, 1)).is_ok());
    }

    #[test]
    fn rejects_outside_with_the_field_named() {
        let err = layout().check(&loc(1, 3, 1, 1, 1)).unwrap_err();
        assert!(err.0.contains("row 3"), "{err}");
        let err = layout().check(&loc(2, 1, 1, 1, 1)).unwrap_err();
        assert!(err.0.contains("aisle 2"), "{err}");
        assert!(layout().check(&loc(1, 1, 1, 0, 1)).is_err());
        assert!(layout().check(&loc(1, 1, 1, 1, 5)).is_err());
    }

    #[test]
    fn enumerates_every_location() {
        assert_eq!(layout().locations().count(), 2 * 10 * 6 * 4);
    }
}
