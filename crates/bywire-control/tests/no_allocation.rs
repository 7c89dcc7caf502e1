//! Nothing on the control path allocates: every `step`, `update`, `apply`, `inverse`,
//! `forward` and `steer` runs under `allocation-counter`'s counting global allocator, which
//! must count zero.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_control::ekf::{Ekf, ProcessNoise};
use bywire_control::kinematics::{four_wheel, Motion, Odometry, Point, Pose, WheelState};
use bywire_control::path::{Geometry, Lookahead, Path, PurePursuit, Stanley};
use bywire_control::pid::{AntiWindup, Pid, PidConfig};
use bywire_control::plant::{Backlash, Lag, Plant};
use bywire_control::stages::{BacklashCompensation, DeadZoneCompensation, RateLimiter};

#[test]
fn the_control_path_never_allocates() {
    // Everything built (and the path's points allocated) before counting starts.
    let mut pid = Pid::new(PidConfig {
        kp: 2.0,
        ki: 1.0,
        kd: 0.1,
        derivative_filter: 0.01,
        output_min: -1.0,
        output_max: 1.0,
        anti_windup: AntiWindup::BackCalculation { tracking_time: 0.5 },
    });
    let mut limiter = RateLimiter::new(1.0, 1.0);
    let dead_zone = DeadZoneCompensation {
        width: 0.2,
        threshold: 0.01,
    };
    let mut backlash = BacklashCompensation::new(0.1, 0.001);
    let mut gear = Backlash { gap: 0.1, y: 0.0 };
    let mut plant = Lag::<3>::new(1.0, 0.5);
    let tug = four_wheel(3.2, 1.8);
    let mut wheels = [WheelState::default(); 4];
    let mut odometry = Odometry::default();
    let mut ekf = Ekf::new(Pose::default(), 1.0, 0.1, ProcessNoise::default());
    let points: Vec<Point> = (0..100)
        .map(|k| Point {
            x: f64::from(k),
            y: 0.1 * f64::from(k),
        })
        .collect();
    let path = Path::new(&points).unwrap();
    let pursuit = PurePursuit {
        lookahead: Lookahead {
            min: 2.0,
            max: 6.0,
            time: 1.0,
        },
        geometry: Geometry::CounterPhase {
            wheelbase: 3.2,
            rear_ratio: 1.0,
        },
        max_steer: 0.6,
    };
    let stanley = Stanley {
        gain: 1.0,
        softening: 0.5,
        front_offset: 1.6,
        geometry: Geometry::Ackermann { wheelbase: 3.2 },
        max_steer: 0.6,
    };

    let mut y = 0.0;
    let mut checksum = 0.0;
    let counted = allocation_counter::measure(|| {
        for k in 0..1_000 {
            let t = f64::from(k) * 0.01;
            let setpoint = limiter.step(0.01, (t * 0.5).sin());
            let u = dead_zone.apply(pid.step(0.01, setpoint, y, 0.0));
            y = plant.step(0.01, gear.apply(backlash.apply(u)));
            let motion = match k % 3 {
                0 => Motion::Normal {
                    speed: 2.0,
                    curvature: 0.05,
                },
                1 => Motion::Crab {
                    speed: 1.0,
                    angle: 0.3,
                },
                _ => Motion::Tank { yaw_rate: 0.2 },
            };
            wheels = tug.inverse(motion.twist(), &wheels);
            let twist = tug.forward(&wheels).unwrap();
            let pose = odometry.update(0.01, twist);
            ekf.predict(0.01);
            ekf.update_odometry(twist.vx, twist.omega, (0.05, 0.01));
            ekf.update_imu(twist.omega, 0.0, (0.01, 0.1));
            ekf.update_gnss(pose.x, pose.y, 0.5);
            let a = pursuit.steer(pose, 2.0, &path);
            let b = stanley.steer(pose, 2.0, &path);
            checksum += a.front + b.front + ekf.pose().x;
        }
    });
    assert!(checksum.is_finite() && y.is_finite());
    assert_eq!(counted.count_total, 0, "allocations on the control path");
    // The counter counts: building a path does allocate (black_box keeps the optimiser from
    // removing the vector in release builds).
    let control = allocation_counter::measure(|| {
        let v: Vec<Point> = std::hint::black_box(vec![Point::default(); 3]);
        assert_eq!(std::hint::black_box(&v).len(), 3);
    });
    assert_eq!(control.count_total, 1);
}
