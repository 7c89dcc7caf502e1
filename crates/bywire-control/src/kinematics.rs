//! Vehicle kinematics and odometry: differential drive, bicycle (Ackermann), and swerve /
//! independent 4-wheel steer with the reference tug's modes (normal 4WS, crab, tank turn).
//!
//! Frames: x forward, y left, angles counter-clockwise in radians, the body twist at the
//! vehicle's reference point (its centre for the 4WS tug).

use core::f64::consts::{FRAC_PI_2, PI};

use crate::math::{self, wrap_angle};

/// A point in the plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// Forward (body) or east (world), m.
    pub x: f64,
    /// Left (body) or north (world), m.
    pub y: f64,
}

/// A body's velocity: forward, leftward and yaw rate.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Forward speed, m/s.
    pub vx: f64,
    /// Leftward speed, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s.
    pub omega: f64,
}

/// A position and heading in the world.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Heading, rad (0 = east), in (−π, π].
    pub yaw: f64,
}

impl Pose {
    /// A world point in this pose's body frame.
    pub fn to_body(&self, p: Point) -> Point {
        let (dx, dy) = (p.x - self.x, p.y - self.y);
        let (s, c) = math::sin_cos(self.yaw);
        Point {
            x: c * dx + s * dy,
            y: -s * dx + c * dy,
        }
    }

    /// A body-frame point in the world.
    pub fn to_world(&self, p: Point) -> Point {
        let (s, c) = math::sin_cos(self.yaw);
        Point {
            x: self.x + c * p.x - s * p.y,
            y: self.y + s * p.x + c * p.y,
        }
    }
}

/// Differential drive: two wheels `track` apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffDrive {
    /// Distance between the wheels, m.
    pub track: f64,
}

impl DiffDrive {
    /// Wheel speeds (left, right) for forward speed `v` and yaw rate `omega`.
    pub fn inverse(&self, v: f64, omega: f64) -> (f64, f64) {
        let half = omega * self.track / 2.0;
        (v - half, v + half)
    }

    /// The body twist from wheel speeds.
    pub fn forward(&self, left: f64, right: f64) -> Twist {
        Twist {
            vx: (left + right) / 2.0,
            vy: 0.0,
            omega: if self.track > 0.0 {
                (right - left) / self.track
            } else {
                0.0
            },
        }
    }
}

/// The bicycle model of an Ackermann vehicle, reference point on the rear axle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bicycle {
    /// Wheelbase, m.
    pub wheelbase: f64,
}

impl Bicycle {
    /// The twist for speed `v` and (front) steering angle `steer`.
    pub fn forward(&self, v: f64, steer: f64) -> Twist {
        Twist {
            vx: v,
            vy: 0.0,
            omega: if self.wheelbase > 0.0 {
                v * math::tan(steer) / self.wheelbase
            } else {
                0.0
            },
        }
    }

    /// The steering angle for a path of `curvature` (1/m, positive left).
    pub fn steer_for_curvature(&self, curvature: f64) -> f64 {
        math::atan(curvature * self.wheelbase)
    }

    /// Inner and outer front wheel angles (true Ackermann) for a turn of `curvature` with the
    /// front wheels `track` apart: (left, right).
    pub fn ackermann_angles(&self, curvature: f64, track: f64) -> (f64, f64) {
        if curvature == 0.0 {
            return (0.0, 0.0);
        }
        let radius = 1.0 / curvature;
        let left = math::atan(self.wheelbase / (radius - track / 2.0));
        let right = math::atan(self.wheelbase / (radius + track / 2.0));
        (left, right)
    }
}

/// One steerable wheel's command or state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelState {
    /// Steering angle, rad, in (−π, π].
    pub angle: f64,
    /// Wheel surface speed along that angle, m/s (negative: rolling backwards).
    pub speed: f64,
}

/// Independently steered and driven wheels at fixed positions (swerve, 4WS).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Swerve<const N: usize> {
    /// Wheel contact points relative to the reference point, m.
    pub wheels: [Point; N],
}

/// Below this speed a wheel keeps its angle: the direction of a zero vector means nothing.
const STANDSTILL: f64 = 1e-9;

impl<const N: usize> Swerve<N> {
    /// Each wheel's angle and speed for `twist`, turning no wheel more than 90° from
    /// `current` (reversing its speed instead).
    pub fn inverse(&self, twist: Twist, current: &[WheelState; N]) -> [WheelState; N] {
        let mut out = *current;
        for ((wheel, now), position) in out.iter_mut().zip(current).zip(&self.wheels) {
            let vx = twist.vx - twist.omega * position.y;
            let vy = twist.vy + twist.omega * position.x;
            let speed = math::hypot(vx, vy);
            if speed < STANDSTILL {
                *wheel = WheelState {
                    angle: now.angle,
                    speed: 0.0,
                };
                continue;
            }
            let angle = math::atan2(vy, vx);
            *wheel = if wrap_angle(angle - now.angle).abs() > FRAC_PI_2 {
                WheelState {
                    angle: wrap_angle(angle + PI),
                    speed: -speed,
                }
            } else {
                WheelState { angle, speed }
            };
        }
        out
    }

    /// The body twist that best explains the wheels' angles and speeds (least squares over
    /// every wheel's two velocity components); `None` for fewer than two wheels at distinct
    /// places.
    pub fn forward(&self, states: &[WheelState; N]) -> Option<Twist> {
        // Normal equations of  v_i = (vx − ω y_i, vy + ω x_i)  in (vx, vy, ω).
        let (mut n, mut sx, mut sy, mut sr2) = (0.0, 0.0, 0.0, 0.0);
        let (mut bx, mut by, mut bw) = (0.0, 0.0, 0.0);
        for (state, p) in states.iter().zip(&self.wheels) {
            let (sin, cos) = math::sin_cos(state.angle);
            let (vx, vy) = (state.speed * cos, state.speed * sin);
            n += 1.0;
            sx += p.x;
            sy += p.y;
            sr2 += p.x * p.x + p.y * p.y;
            bx += vx;
            by += vy;
            bw += -p.y * vx + p.x * vy;
        }
        // [ n   0  −sy ] [vx]   [bx]
        // [ 0   n   sx ] [vy] = [by]
        // [−sy  sx sr2 ] [ω ]   [bw]
        let det = n * (n * sr2 - sx * sx) - sy * sy * n;
        if det.abs() < 1e-12 {
            return None;
        }
        let omega = (n * bw + sy * bx - sx * by) / (n * sr2 - sx * sx - sy * sy);
        Some(Twist {
            vx: (bx + sy * omega) / n,
            vy: (by - sx * omega) / n,
            omega,
        })
    }
}

/// How the reference tug moves its four steered wheels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Normal 4WS: front and rear in counter-phase, turning about a point abreast of the
    /// centre, on a path of `curvature` (1/m, positive left).
    Normal {
        /// Speed, m/s.
        speed: f64,
        /// Path curvature, 1/m.
        curvature: f64,
    },
    /// Crab: every wheel at `angle`, the body moving sideways without turning.
    Crab {
        /// Speed, m/s.
        speed: f64,
        /// Direction of travel relative to the body, rad.
        angle: f64,
    },
    /// Tank turn: rotation on the spot.
    Tank {
        /// Yaw rate, rad/s.
        yaw_rate: f64,
    },
}

impl Motion {
    /// The body twist at the centre.
    pub fn twist(self) -> Twist {
        match self {
            Motion::Normal { speed, curvature } => Twist {
                vx: speed,
                vy: 0.0,
                omega: speed * curvature,
            },
            Motion::Crab { speed, angle } => Twist {
                vx: speed * math::cos(angle),
                vy: speed * math::sin(angle),
                omega: 0.0,
            },
            Motion::Tank { yaw_rate } => Twist {
                vx: 0.0,
                vy: 0.0,
                omega: yaw_rate,
            },
        }
    }
}

/// The four wheels of a rectangular 4WS vehicle centred on its reference point, in the order
/// front-left, front-right, rear-left, rear-right.
pub fn four_wheel(wheelbase: f64, track: f64) -> Swerve<4> {
    let (a, b) = (wheelbase / 2.0, track / 2.0);
    Swerve {
        wheels: [
            Point { x: a, y: b },
            Point { x: a, y: -b },
            Point { x: -a, y: b },
            Point { x: -a, y: -b },
        ],
    }
}

/// Dead reckoning: the pose integrated from body twists.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Odometry {
    /// The current pose.
    pub pose: Pose,
    /// Distance travelled by the reference point, m.
    pub distance: f64,
}

impl Odometry {
    /// Start at `pose`.
    pub fn new(pose: Pose) -> Self {
        Odometry {
            pose,
            distance: 0.0,
        }
    }

    /// Move with `twist` held for `dt` seconds (exact for a constant twist: an arc).
    /// Non-finite twists and non-positive `dt` change nothing.
    pub fn update(&mut self, dt: f64, twist: Twist) -> Pose {
        let valid = dt > 0.0
            && dt.is_finite()
            && twist.vx.is_finite()
            && twist.vy.is_finite()
            && twist.omega.is_finite();
        if !valid {
            return self.pose;
        }
        let Pose { x, y, yaw } = self.pose;
        let turn = twist.omega * dt;
        let (dx, dy) = if turn.abs() < 1e-9 {
            // Straight: rotate the body displacement at the mid heading.
            let mid = yaw + turn / 2.0;
            let (s, c) = math::sin_cos(mid);
            (
                (twist.vx * c - twist.vy * s) * dt,
                (twist.vx * s + twist.vy * c) * dt,
            )
        } else {
            let (s0, c0) = math::sin_cos(yaw);
            let (s1, c1) = math::sin_cos(yaw + turn);
            (
                (twist.vx * (s1 - s0) + twist.vy * (c1 - c0)) / twist.omega,
                (-twist.vx * (c1 - c0) + twist.vy * (s1 - s0)) / twist.omega,
            )
        };
        self.pose = Pose {
            x: x + dx,
            y: y + dy,
            yaw: wrap_angle(yaw + turn),
        };
        self.distance += math::hypot(twist.vx, twist.vy) * dt;
        self.pose
    }
}
