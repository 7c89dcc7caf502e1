//! Kinematics, odometry and path following: swerve inverse/forward round trips, the 4WS modes'
//! geometry, and followers that bring a simulated vehicle onto a path.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::f64::consts::{FRAC_PI_2, PI};

use bywire_control::kinematics::{
    four_wheel, Bicycle, DiffDrive, Motion, Odometry, Point, Pose, Twist, WheelState,
};
use bywire_control::path::{Geometry, Lookahead, Path, PurePursuit, Stanley};
use proptest::prelude::*;

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

proptest! {
    /// Looking first at any segment (the right one, a wrong one, one past the end) gives the
    /// projection a full search gives, on paths that double back and cross themselves.
    #[test]
    fn a_projection_is_the_same_whichever_segment_is_looked_at_first(
        corners in prop::collection::vec((-50.0..50.0f64, -50.0..50.0f64), 2..40),
        x in -60.0..60.0f64, y in -60.0..60.0f64,
        near in 0usize..45,
    ) {
        let points: Vec<Point> = corners.iter().map(|&(x, y)| Point { x, y }).collect();
        let path = Path::new(&points).unwrap();
        let p = Point { x, y };
        let full = path.project(p);
        prop_assert_eq!(path.project_near(p, Some(near)), full);
        prop_assert_eq!(path.project_near(p, Some(full.segment)), full);
    }

    #[test]
    fn swerve_forward_inverts_inverse(
        vx in -5.0..5.0f64, vy in -5.0..5.0f64, omega in -2.0..2.0f64,
        current in proptest::array::uniform4(-PI..PI),
    ) {
        let tug = four_wheel(3.2, 1.8);
        let now = current.map(|angle| WheelState { angle, speed: 0.0 });
        let twist = Twist { vx, vy, omega };
        let wheels = tug.inverse(twist, &now);
        let back = tug.forward(&wheels).unwrap();
        prop_assert!(close(back.vx, vx) && close(back.vy, vy) && close(back.omega, omega),
            "{twist:?} -> {wheels:?} -> {back:?}");
        // No wheel turns more than 90° from where it was.
        for (w, n) in wheels.iter().zip(&now) {
            prop_assert!(wrap(w.angle - n.angle).abs() <= FRAC_PI_2 + 1e-12);
        }
    }

    #[test]
    fn diff_drive_round_trips(v in -5.0..5.0f64, omega in -3.0..3.0f64) {
        let d = DiffDrive { track: 0.6 };
        let (l, r) = d.inverse(v, omega);
        let t = d.forward(l, r);
        prop_assert!(close(t.vx, v) && close(t.omega, omega));
    }

    #[test]
    fn odometry_of_a_constant_turn_stays_on_its_circle(v in 0.1..5.0f64, omega in 0.05..1.0f64) {
        let mut odometry = Odometry::default();
        for _ in 0..1_000 {
            odometry.update(0.01, Twist { vx: v, vy: 0.0, omega });
        }
        // Circle of radius v/ω centred at (0, v/ω).
        let r = v / omega;
        let p = odometry.pose;
        prop_assert!((p.x.hypot(p.y - r) - r).abs() < 1e-9 * r.max(1.0) * 1e3);
        prop_assert!(close(p.yaw, wrap(omega * 10.0)));
        prop_assert!((odometry.distance - v * 10.0).abs() < 1e-9);
    }
}

#[test]
fn tank_turn_puts_every_wheel_tangent_to_a_circle() {
    let tug = four_wheel(3.2, 1.8);
    let wheels = tug.inverse(
        Motion::Tank { yaw_rate: 0.5 }.twist(),
        &[WheelState::default(); 4],
    );
    let radius = (1.6f64).hypot(0.9);
    for (w, p) in wheels.iter().zip(&tug.wheels) {
        // Direction of travel perpendicular to the radius, speed ω·r.
        let dot = w.angle.cos() * p.x + w.angle.sin() * p.y;
        assert!(dot.abs() < 1e-12, "{w:?} at {p:?}");
        assert!(close(w.speed.abs(), 0.5 * radius));
    }
    // The body does not move.
    let back = tug.forward(&wheels).unwrap();
    assert!(close(back.vx, 0.0) && close(back.vy, 0.0) && close(back.omega, 0.5));
}

#[test]
fn crab_puts_all_wheels_parallel() {
    let tug = four_wheel(3.2, 1.8);
    let wheels = tug.inverse(
        Motion::Crab {
            speed: 1.5,
            angle: 0.6,
        }
        .twist(),
        &[WheelState::default(); 4],
    );
    for w in &wheels {
        assert!(close(w.angle, 0.6) && close(w.speed, 1.5), "{w:?}");
    }
}

#[test]
fn normal_4ws_steers_front_and_rear_in_counter_phase() {
    let tug = four_wheel(3.2, 1.8);
    let wheels = tug.inverse(
        Motion::Normal {
            speed: 2.0,
            curvature: 0.1,
        }
        .twist(),
        &[WheelState::default(); 4],
    );
    let [fl, fr, rl, rr] = wheels;
    assert!(fl.angle > 0.0 && fr.angle > 0.0);
    assert!(close(rl.angle, -fl.angle) && close(rr.angle, -fr.angle));
    // Inner (left) wheels turn more than outer ones, as Ackermann asks.
    assert!(fl.angle > fr.angle);
    // Every wheel's axis passes through the turn centre (0, 1/κ).
    for (w, p) in wheels.iter().zip(&tug.wheels) {
        let to_centre = (0.0 - p.x, 10.0 - p.y);
        let dot = w.angle.cos() * to_centre.0 + w.angle.sin() * to_centre.1;
        assert!(dot.abs() < 1e-9, "{w:?} at {p:?}");
    }
}

#[test]
fn bicycle_and_ackermann_agree() {
    let b = Bicycle { wheelbase: 2.5 };
    let steer = b.steer_for_curvature(0.2);
    assert!(close(b.forward(3.0, steer).omega, 0.6));
    let (left, right) = b.ackermann_angles(0.2, 1.5);
    assert!(left > steer && steer > right);
    assert!(close(2.5 / left.tan() - 2.5 / right.tan(), -1.5));
}

/// Simulate a vehicle following `path` from `start`; the largest cross-track error over the
/// last half of the run, and the final pose.
fn follow(
    start: Pose,
    speed: f64,
    path_points: &[Point],
    steer: &dyn Fn(Pose, &Path<'_>) -> (f64, f64),
    geometry: Geometry,
) -> (f64, Pose) {
    let path = Path::new(path_points).unwrap();
    let mut odometry = Odometry::new(start);
    let mut worst: f64 = 0.0;
    let steps = 3_000;
    for k in 0..steps {
        let (front, rear) = steer(odometry.pose, &path);
        let twist = match geometry {
            Geometry::Ackermann { wheelbase } => Bicycle { wheelbase }.forward(speed, front),
            Geometry::CounterPhase { wheelbase, .. } => Twist {
                vx: speed,
                vy: 0.0,
                omega: speed * (front.tan() - rear.tan()) / wheelbase,
            },
            Geometry::Crab => Twist {
                vx: speed * front.cos(),
                vy: speed * front.sin(),
                omega: 0.0,
            },
        };
        odometry.update(0.01, twist);
        if k > steps / 2 {
            let p = odometry.pose;
            worst = worst.max(path.project(Point { x: p.x, y: p.y }).offset.abs());
        }
    }
    (worst, odometry.pose)
}

fn straight() -> Vec<Point> {
    vec![Point { x: -10.0, y: 0.0 }, Point { x: 200.0, y: 0.0 }]
}

fn circle(radius: f64) -> Vec<Point> {
    (0..=720)
        .map(|k| {
            let a = f64::from(k) * PI / 360.0 - FRAC_PI_2;
            Point {
                x: radius * a.cos(),
                y: radius + radius * a.sin(),
            }
        })
        .collect()
}

#[test]
fn pure_pursuit_converges_for_every_geometry() {
    let start = Pose {
        x: 0.0,
        y: 2.0,
        yaw: 0.3,
    };
    for geometry in [
        Geometry::Ackermann { wheelbase: 3.2 },
        Geometry::CounterPhase {
            wheelbase: 3.2,
            rear_ratio: 1.0,
        },
        Geometry::Crab,
    ] {
        let follower = PurePursuit {
            lookahead: Lookahead {
                min: 2.0,
                max: 8.0,
                time: 1.0,
            },
            geometry,
            max_steer: 0.6,
        };
        let start = if geometry == Geometry::Crab {
            Pose { yaw: 0.0, ..start }
        } else {
            start
        };
        let (worst, end) = follow(
            start,
            2.0,
            &straight(),
            &|pose, path| {
                let c = follower.steer(pose, 2.0, path);
                // Given the projection a caller already has, the same command.
                let here = Point {
                    x: pose.x,
                    y: pose.y,
                };
                let from = follower.steer_from(pose, 2.0, path, &path.project(here));
                assert_eq!(c, from);
                (c.front, c.rear)
            },
            geometry,
        );
        assert!(worst < 0.05, "{geometry:?}: {worst}");
        if geometry == Geometry::Crab {
            assert_eq!(end.yaw, 0.0, "crab never turns the body");
        }
    }
}

#[test]
fn pure_pursuit_holds_a_circle() {
    let geometry = Geometry::Ackermann { wheelbase: 3.2 };
    let follower = PurePursuit {
        lookahead: Lookahead {
            min: 3.0,
            max: 3.0,
            time: 0.0,
        },
        geometry,
        max_steer: 0.6,
    };
    let (worst, _) = follow(
        Pose::default(),
        2.0,
        &circle(15.0),
        &|pose, path| {
            let c = follower.steer(pose, 2.0, path);
            (c.front, c.rear)
        },
        geometry,
    );
    // Pure pursuit cuts corners slightly on a curve: bounded by ld²/(2R)·… well under 0.3 m.
    assert!(worst < 0.3, "{worst}");
}

#[test]
fn stanley_converges_for_ackermann_and_4ws() {
    for (geometry, offset) in [
        (Geometry::Ackermann { wheelbase: 3.2 }, 3.2),
        (
            Geometry::CounterPhase {
                wheelbase: 3.2,
                rear_ratio: 0.5,
            },
            1.6,
        ),
    ] {
        let follower = Stanley {
            gain: 1.5,
            softening: 0.5,
            front_offset: offset,
            geometry,
            max_steer: 0.6,
        };
        let (worst, end) = follow(
            Pose {
                x: 0.0,
                y: -1.5,
                yaw: -0.2,
            },
            2.0,
            &straight(),
            &|pose, path| {
                let c = follower.steer(pose, 2.0, path);
                (c.front, c.rear)
            },
            geometry,
        );
        assert!(worst < 0.05, "{geometry:?}: {worst}");
        assert!(end.yaw.abs() < 0.01, "{geometry:?}: {end:?}");
    }
}

#[test]
fn paths_need_two_points_and_project_with_a_side() {
    assert!(Path::new(&[Point::default()]).is_none());
    let points = straight();
    let path = Path::new(&points).unwrap();
    assert!(close(path.length(), 210.0));
    let left = path.project(Point { x: 5.0, y: 1.0 });
    assert!(close(left.offset, -1.0) && close(left.station, 15.0));
    let right = path.project(Point { x: 5.0, y: -2.0 });
    assert!(close(right.offset, 2.0));
    assert_eq!(path.at_station(1e9), Point { x: 200.0, y: 0.0 });
}

/// Two segments equally near: the first along the path is the answer, whichever is looked at
/// first.
#[test]
fn a_tie_goes_to_the_first_segment_whichever_is_looked_at_first() {
    let points = [
        Point { x: -5.0, y: 0.0 },
        Point { x: 5.0, y: 0.0 },
        Point { x: 5.0, y: 10.0 },
        Point { x: -5.0, y: 10.0 },
    ];
    let path = Path::new(&points).unwrap();
    let p = Point { x: 0.0, y: 5.0 };
    for near in [None, Some(0), Some(1), Some(2), Some(7)] {
        let projection = path.project_near(p, near);
        assert_eq!(projection.segment, 0, "{near:?}");
        assert_eq!(projection.point, Point { x: 0.0, y: 0.0 });
        assert_eq!(projection, path.project(p));
    }
}
