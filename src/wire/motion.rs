//! How a stacker crane moves, in numbers: the travel axis (along the aisle, bay by bay) and
//! the lift axis (level by level) each on a trapezoidal speed profile (accelerate, cruise,
//! brake), both at once, so a move takes as long as its slower axis; a fork cycle at each
//! end (extend, lift or lower, retract), longer at a far position.
//!
//! Shared by the crane simulator (which moves its D220/D221 by it and takes the time it
//! says) and the crane planner (which ranks work by the time it costs), so what the planner
//! saves is what the simulated crane spends. The spec gives no figures; the defaults are
//! those of a common pallet stacker crane (travel 3 m/s at 0.5 m/s², lift 1 m/s at
//! 0.5 m/s², a 1.4 m bay, a 1.5 m level, 6 s per fork cycle near and 9 s far), and every
//! one is configurable (`[devices.motion]` for a crane, options of `rackd sim crane`).
//!
//! Positions are in metres from the origin (bay 0, level 0): the station bay is bay 0.

use serde::{Deserialize, Serialize};

/// One axis: top speed and acceleration (braking is as hard).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Top speed, m/s.
    pub speed: f64,
    /// Acceleration and deceleration, m/s².
    pub accel: f64,
}

impl Axis {
    /// Seconds to cover `distance` metres from standstill to standstill.
    pub fn time(&self, distance: f64) -> f64 {
        let d = distance.abs();
        if d == 0.0 {
            return 0.0;
        }
        let ramp = self.speed * self.speed / self.accel;
        if d < ramp { 2.0 * (d / self.accel).sqrt() } else { d / self.speed + self.speed / self.accel }
    }

    /// Metres covered `t` seconds into a move of `distance` metres (clamped to the move).
    pub fn covered(&self, distance: f64, t: f64) -> f64 {
        let d = distance.abs();
        let total = self.time(d);
        if t <= 0.0 || d == 0.0 {
            return 0.0;
        }
        if t >= total {
            return d;
        }
        // Time spent accelerating (and, symmetrically, braking), and the top speed reached.
        let t_ramp = (self.speed / self.accel).min(total / 2.0);
        let top = self.accel * t_ramp;
        if t < t_ramp {
            0.5 * self.accel * t * t
        } else if t < total - t_ramp {
            0.5 * self.accel * t_ramp * t_ramp + top * (t - t_ramp)
        } else {
            let left = total - t;
            d - 0.5 * self.accel * left * left
        }
    }
}

/// A crane's motion model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Motion {
    /// The travel axis (along the aisle).
    pub travel: Axis,
    /// The lift axis.
    pub lift: Axis,
    /// Width of a bay, m.
    pub bay_width: f64,
    /// Height of a level, m.
    pub level_height: f64,
    /// Seconds of a fork cycle at a near position (position 1) or a station.
    pub fork_near: f64,
    /// Seconds of a fork cycle at a far position (position 2 and beyond).
    pub fork_far: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Motion {
            travel: Axis { speed: 3.0, accel: 0.5 },
            lift: Axis { speed: 1.0, accel: 0.5 },
            bay_width: 1.4,
            level_height: 1.5,
            fork_near: 6.0,
            fork_far: 9.0,
        }
    }
}

/// Where the crane stands: a bay and a level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Spot {
    /// Bay (0: the station bay).
    pub bay: u16,
    /// Level.
    pub level: u16,
}

impl Motion {
    /// Metres along each axis of a spot: (travel, lift).
    pub fn metres(&self, at: Spot) -> (f64, f64) {
        (at.bay as f64 * self.bay_width, at.level as f64 * self.level_height)
    }

    /// Seconds to move from one spot to another, both axes at once.
    pub fn move_time(&self, from: Spot, to: Spot) -> f64 {
        self.between(self.metres(from), self.metres(to))
    }

    /// Seconds to move between two points given in metres (travel, lift), both axes at
    /// once: a crane halted or cancelled between two spots moves on from where it stands.
    pub fn between(&self, from: (f64, f64), to: (f64, f64)) -> f64 {
        self.travel.time(to.0 - from.0).max(self.lift.time(to.1 - from.1))
    }

    /// Where a move between two points in metres stands `t` seconds after it started; each
    /// axis on its own profile, so the shorter one arrives first and waits.
    pub fn along(&self, from: (f64, f64), to: (f64, f64), t: f64) -> (f64, f64) {
        let step = |axis: &Axis, a: f64, b: f64| a + (b - a).signum() * axis.covered(b - a, t);
        (step(&self.travel, from.0, to.0), step(&self.lift, from.1, to.1))
    }

    /// Seconds of one fork cycle at `position` (1 near; 2 and beyond far; 0 a station).
    pub fn fork_time(&self, position: u16) -> f64 {
        if position >= 2 { self.fork_far } else { self.fork_near }
    }

    /// Whether every figure is positive and finite (what a configuration must hold).
    pub fn is_valid(&self) -> bool {
        [
            self.travel.speed,
            self.travel.accel,
            self.lift.speed,
            self.lift.accel,
            self.bay_width,
            self.level_height,
            self.fork_near,
            self.fork_far,
        ]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_move_never_reaches_top_speed() {
        let axis = Axis { speed: 3.0, accel: 0.5 };
        // Ramp distance 18 m: 8 m is accelerate 4 m, brake 4 m: 2 * sqrt(8 / 0.5) = 8 s.
        assert!((axis.time(8.0) - 8.0).abs() < 1e-9);
        // 36 m: 36 / 3 + 3 / 0.5 = 18 s.
        assert!((axis.time(36.0) - 18.0).abs() < 1e-9);
        assert_eq!(axis.time(0.0), 0.0);
        assert_eq!(axis.time(-36.0), axis.time(36.0));
    }

    #[test]
    fn covered_follows_the_profile_to_the_end() {
        let axis = Axis { speed: 3.0, accel: 0.5 };
        for d in [0.5, 8.0, 18.0, 36.0, 84.0] {
            let total = axis.time(d);
            assert_eq!(axis.covered(d, 0.0), 0.0);
            assert!((axis.covered(d, total) - d).abs() < 1e-9);
            assert!((axis.covered(d, total / 2.0) - d / 2.0).abs() < 1e-9, "symmetric at {d}");
            let mut last = 0.0;
            for i in 1..=100 {
                let now = axis.covered(d, total * i as f64 / 100.0);
                assert!(now >= last - 1e-12, "never backwards at {d}");
                last = now;
            }
        }
    }

    #[test]
    fn a_move_takes_its_slower_axis() {
        let m = Motion::default();
        let station = Spot { bay: 0, level: 1 };
        let far_low = Spot { bay: 40, level: 1 };
        let near_high = Spot { bay: 1, level: 10 };
        assert_eq!(m.move_time(station, far_low), m.travel.time(40.0 * 1.4));
        assert_eq!(m.move_time(station, near_high), m.lift.time(9.0 * 1.5));
        assert!(m.fork_time(2) > m.fork_time(1));
        assert!(m.is_valid());
        assert!(!Motion { bay_width: 0.0, ..m }.is_valid());
    }

    #[test]
    fn along_goes_both_ways_and_ends_at_the_target() {
        let m = Motion::default();
        let (a, b) = ((14.0, 1.5), (2.8, 6.0));
        let total = m.between(a, b);
        assert_eq!(m.along(a, b, 0.0), a);
        let end = m.along(a, b, total);
        assert!((end.0 - b.0).abs() < 1e-9 && (end.1 - b.1).abs() < 1e-9, "{end:?}");
        let mid = m.along(a, b, total / 2.0);
        assert!(mid.0 < a.0 && mid.0 > b.0 && mid.1 > a.1, "{mid:?}");
        assert_eq!(m.along(a, a, 3.0), a);
    }
}
