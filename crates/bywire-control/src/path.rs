//! Path following: pure pursuit and Stanley, for Ackermann steering and for 4-wheel steering
//! (front and rear in counter-phase, or crab with all wheels in phase).
//!
//! A path is a polyline of world points (at least two). The followers return a steering
//! command per axle; they allocate nothing and walk the path once per call.

use crate::kinematics::{Point, Pose};
use crate::math::{self, wrap_angle};

/// Where a point lies relative to a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Index of the segment (from point `segment` to `segment + 1`).
    pub segment: usize,
    /// The nearest point on the path.
    pub point: Point,
    /// Arc length from the path's start to that point, m.
    pub station: f64,
    /// Signed distance to the path, positive when the path passes to the point's left
    /// (seen along the path's direction).
    pub offset: f64,
    /// Direction of the path there, rad.
    pub heading: f64,
}

/// A polyline to follow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Path<'a> {
    points: &'a [Point],
}

impl<'a> Path<'a> {
    /// A path through `points`; `None` with fewer than two.
    pub fn new(points: &'a [Point]) -> Option<Self> {
        (points.len() >= 2).then_some(Path { points })
    }

    fn segments(&self) -> impl Iterator<Item = (usize, Point, Point)> + 'a {
        self.points
            .windows(2)
            .enumerate()
            .filter_map(|(i, w)| match w {
                [a, b] => Some((i, *a, *b)),
                _ => None,
            })
    }

    /// The path's length, m.
    pub fn length(&self) -> f64 {
        self.segments()
            .map(|(_, a, b)| math::hypot(b.x - a.x, b.y - a.y))
            .sum()
    }

    /// The nearest point of the path to `p`. `offset` is positive when the path passes to
    /// the left of `p` (seen along the path's direction, `p` is on its right).
    pub fn project(&self, p: Point) -> Projection {
        self.project_near(p, None)
    }

    /// [`Path::project`], looking first at segment `near` (where `p` was found last time, for
    /// a follower that projects every cycle): the answer is the same whatever `near` says, but
    /// with a good guess the segments whose bounding boxes lie clearly beyond it are passed
    /// over without projecting onto them.
    pub fn project_near(&self, p: Point, near: Option<usize>) -> Projection {
        // No segment whose box is farther than the guess's nearest point can be the nearest
        // (the margin is far beyond rounding), nor tie with it.
        let bound = near
            .and_then(|i| self.points.get(i..i.saturating_add(2)))
            .and_then(|w| match w {
                [a, b] => Some(Foot::on(*a, *b, p).squared * (1.0 + 1e-6)),
                _ => None,
            });
        // The nearest by `hypot`, as ever; a segment whose squared distance is clearly more
        // than the best's cannot be nearer by `hypot` (whose error is an ulp), so it is passed
        // over without one. The heading is worked out for the nearest alone.
        let mut best: Option<(f64, f64, Projection, (f64, f64))> = None;
        let mut station = 0.0;
        for (segment, a, b) in self.segments() {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            let len = math::sqrt(dx * dx + dy * dy);
            if bound.is_some_and(|bound| box_squared(a, b, p) > bound) {
                station += len;
                continue;
            }
            let Foot {
                t,
                point,
                ex,
                ey,
                squared,
            } = Foot::on(a, b, p);
            let clearly_farther = best
                .as_ref()
                .is_some_and(|(_, best_squared, _, _)| squared > best_squared * (1.0 + 1e-9));
            if !clearly_farther {
                let distance = math::hypot(ex, ey);
                if best.as_ref().is_none_or(|(d, _, _, _)| distance < *d) {
                    // Cross product of the path direction with (p − point): negative when p
                    // is on the right, i.e. the path is to its left.
                    let cross = dx * ey - dy * ex;
                    let side = if cross > 0.0 { -1.0 } else { 1.0 };
                    let projection = Projection {
                        segment,
                        point,
                        station: station + t * len,
                        offset: side * distance,
                        heading: 0.0,
                    };
                    best = Some((distance, squared, projection, (dx, dy)));
                }
            }
            station += len;
        }
        best.map_or(
            Projection {
                segment: 0,
                point: p,
                station: 0.0,
                offset: 0.0,
                heading: 0.0,
            },
            |(_, _, projection, (dx, dy))| Projection {
                heading: math::atan2(dy, dx),
                ..projection
            },
        )
    }

    /// The point `station` metres along the path (clamped to its ends).
    pub fn at_station(&self, station: f64) -> Point {
        let mut walked = 0.0;
        let mut last = self.points.first().copied().unwrap_or_default();
        for (_, a, b) in self.segments() {
            let len = math::hypot(b.x - a.x, b.y - a.y);
            if station <= walked + len && len > 0.0 {
                let t = ((station - walked) / len).clamp(0.0, 1.0);
                return Point {
                    x: a.x + t * (b.x - a.x),
                    y: a.y + t * (b.y - a.y),
                };
            }
            walked += len;
            last = b;
        }
        last
    }
}

/// The foot of the perpendicular from `p` onto segment `a`–`b` (clamped to it): where along
/// it (0–1), the point, and `p`'s offset from it, also squared.
struct Foot {
    t: f64,
    point: Point,
    ex: f64,
    ey: f64,
    squared: f64,
}

impl Foot {
    fn on(a: Point, b: Point, p: Point) -> Foot {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((p.x - a.x) * dx + (p.y - a.y) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let point = Point {
            x: a.x + t * dx,
            y: a.y + t * dy,
        };
        let (ex, ey) = (p.x - point.x, p.y - point.y);
        Foot {
            t,
            point,
            ex,
            ey,
            squared: ex * ex + ey * ey,
        }
    }
}

/// The squared distance from `p` to the bounding box of segment `a`–`b` (no more than to
/// any point of the segment).
fn box_squared(a: Point, b: Point, p: Point) -> f64 {
    let outside = |p: f64, a: f64, b: f64| (a.min(b) - p).max(p - a.max(b)).max(0.0);
    let (gx, gy) = (outside(p.x, a.x, b.x), outside(p.y, a.y, b.y));
    gx * gx + gy * gy
}

/// How the vehicle steers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geometry {
    /// Front-axle steering; the pose is the rear axle's centre.
    Ackermann {
        /// Wheelbase, m.
        wheelbase: f64,
    },
    /// Four-wheel steering in counter-phase: `tan(rear) = −ratio · tan(front)`, the pose at
    /// the vehicle's centre (ratio 1 turns about a point abreast of the centre).
    CounterPhase {
        /// Wheelbase, m.
        wheelbase: f64,
        /// Rear-to-front steering ratio, 0..=1.
        rear_ratio: f64,
    },
    /// Crab: all wheels at one angle, the heading held; the pose at the centre.
    Crab,
}

/// Steering angles per axle, rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SteeringCommand {
    /// Front axle.
    pub front: f64,
    /// Rear axle.
    pub rear: f64,
}

impl Geometry {
    /// The axle angles that make the reference point follow `curvature` (Ackermann and
    /// counter-phase), limited to ±`max_steer`.
    fn for_curvature(self, curvature: f64, max_steer: f64) -> SteeringCommand {
        let limit = |a: f64| a.clamp(-max_steer, max_steer);
        match self {
            Geometry::Ackermann { wheelbase } => SteeringCommand {
                front: limit(math::atan(curvature * wheelbase)),
                rear: 0.0,
            },
            Geometry::CounterPhase {
                wheelbase,
                rear_ratio,
            } => {
                // Curvature at the centre with tan δr = −r tan δf (rigid-body kinematics of
                // a vehicle steered at ±L/2): κ = (tan δf − tan δr) / L.
                let tan_front = curvature * wheelbase / (1.0 + rear_ratio);
                let front = limit(math::atan(tan_front));
                SteeringCommand {
                    front,
                    rear: math::atan(-rear_ratio * math::tan(front)),
                }
            }
            Geometry::Crab => SteeringCommand::default(),
        }
    }
}

/// Lookahead distance scheduled by speed: `min + time · |v|`, at most `max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lookahead {
    /// At standstill, m.
    pub min: f64,
    /// Upper bound, m.
    pub max: f64,
    /// Seconds of travel added per m/s.
    pub time: f64,
}

impl Lookahead {
    /// The distance at `speed`.
    pub fn at(&self, speed: f64) -> f64 {
        (self.min + self.time * speed.abs()).clamp(self.min, self.max.max(self.min))
    }
}

/// Pure pursuit: steer onto the arc through the point one lookahead distance ahead on the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PurePursuit {
    /// Lookahead schedule.
    pub lookahead: Lookahead,
    /// Steering geometry.
    pub geometry: Geometry,
    /// Largest steering angle, rad.
    pub max_steer: f64,
}

impl PurePursuit {
    /// The steering command for a vehicle at `pose` moving at `speed` along `path`.
    pub fn steer(&self, pose: Pose, speed: f64, path: &Path<'_>) -> SteeringCommand {
        let here = Point {
            x: pose.x,
            y: pose.y,
        };
        self.steer_from(pose, speed, path, &path.project(here))
    }

    /// The same, given where `pose` projects onto `path` (`path.project` of its position),
    /// for a caller that needs the projection too.
    pub fn steer_from(
        &self,
        pose: Pose,
        speed: f64,
        path: &Path<'_>,
        projection: &Projection,
    ) -> SteeringCommand {
        let target = path.at_station(projection.station + self.lookahead.at(speed));
        let local = pose.to_body(target);
        let distance = math::hypot(local.x, local.y);
        if distance < 1e-9 {
            return SteeringCommand::default();
        }
        let alpha = math::atan2(local.y, local.x);
        match self.geometry {
            Geometry::Crab => {
                // Head straight for the target without turning the body.
                let angle = alpha.clamp(-self.max_steer, self.max_steer);
                SteeringCommand {
                    front: angle,
                    rear: angle,
                }
            }
            geometry => {
                let curvature = 2.0 * math::sin(alpha) / distance;
                geometry.for_curvature(curvature, self.max_steer)
            }
        }
    }
}

/// Stanley: heading error plus `atan(k · e / (soft + v))` for the cross-track error `e` of the
/// steered axle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stanley {
    /// Cross-track gain, 1/s.
    pub gain: f64,
    /// Softening speed, m/s (keeps the correction finite at standstill).
    pub softening: f64,
    /// Distance from the pose to the front axle, m (0 for crab).
    pub front_offset: f64,
    /// Steering geometry.
    pub geometry: Geometry,
    /// Largest steering angle, rad.
    pub max_steer: f64,
}

impl Stanley {
    /// The steering command for a vehicle at `pose` moving at `speed` along `path`.
    pub fn steer(&self, pose: Pose, speed: f64, path: &Path<'_>) -> SteeringCommand {
        let axle = pose.to_world(Point {
            x: self.front_offset,
            y: 0.0,
        });
        let projection = path.project(axle);
        let heading_error = wrap_angle(projection.heading - pose.yaw);
        let correction = math::atan(self.gain * projection.offset / (self.softening + speed.abs()));
        let angle = wrap_angle(heading_error + correction).clamp(-self.max_steer, self.max_steer);
        match self.geometry {
            Geometry::Ackermann { .. } => SteeringCommand {
                front: angle,
                rear: 0.0,
            },
            Geometry::CounterPhase { rear_ratio, .. } => SteeringCommand {
                front: angle,
                rear: math::atan(-rear_ratio * math::tan(angle)),
            },
            Geometry::Crab => SteeringCommand {
                front: angle,
                rear: angle,
            },
        }
    }
}
