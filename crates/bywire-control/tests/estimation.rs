//! The EKF on a simulated drive: noisy wheel odometry (50 Hz), IMU (100 Hz) and GNSS (5 Hz)
//! with multipath outliers. The position error stays inside the filter's own 3σ bound at least
//! 99 % of the time and every outlier is rejected.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_control::ekf::{Ekf, ProcessNoise, Update};
use bywire_control::kinematics::{Odometry, Pose, Twist};

/// Standard normal samples (Box–Muller) from a seeded generator.
struct Noise(fastrand::Rng);

impl Noise {
    fn gauss(&mut self, sigma: f64) -> f64 {
        let u1 = self.0.f64().max(1e-300);
        let u2 = self.0.f64();
        sigma * (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// χ² with 2 degrees of freedom at 99.73 % (the 3σ probability).
const THREE_SIGMA_2DOF: f64 = 11.83;

#[test]
fn ekf_stays_within_its_bound_and_rejects_outliers() {
    for seed in [1, 2] {
        let mut noise = Noise(fastrand::Rng::with_seed(seed));
        let mut truth = Odometry::new(Pose::default());
        let mut ekf = Ekf::new(Pose::default(), 0.5, 0.05, ProcessNoise::default());
        let dt = 0.01;
        let (mut inside, mut checks) = (0u32, 0u32);
        let (mut outliers, mut rejected_outliers, mut rejected_inliers) = (0, 0, 0);
        let mut speed: f64 = 0.0;
        for k in 0..30_000u32 {
            let t = f64::from(k) * dt;
            // A drive with speed changes and turns: 5 minutes around an apron.
            let accel = 0.3 * (0.05 * t).sin();
            speed = (speed + accel * dt).clamp(0.0, 4.0);
            let yaw_rate = 0.15 * (0.02 * t).sin();
            let twist = Twist {
                vx: speed,
                vy: 0.0,
                omega: yaw_rate,
            };
            truth.update(dt, twist);
            ekf.predict(dt);
            ekf.update_imu(
                yaw_rate + noise.gauss(0.005),
                accel + noise.gauss(0.05),
                (0.005, 0.05),
            );
            if k % 2 == 0 {
                ekf.update_odometry(
                    speed + noise.gauss(0.05),
                    yaw_rate + noise.gauss(0.02),
                    (0.05, 0.02),
                );
            }
            if k % 20 == 0 {
                let outlier = noise.0.f64() < 0.05;
                let jump = if outlier { 15.0 } else { 0.0 };
                let p = truth.pose;
                let result = ekf.update_gnss(
                    p.x + noise.gauss(0.5) + jump,
                    p.y + noise.gauss(0.5) - jump,
                    0.5,
                );
                match (outlier, result) {
                    (true, Update::Rejected(_)) => rejected_outliers += 1,
                    (false, Update::Rejected(_)) => rejected_inliers += 1,
                    _ => {}
                }
                outliers += u32::from(outlier);
                // Position error against the filter's own covariance.
                let e = ekf.pose();
                let (dx, dy) = (e.x - p.x, e.y - p.y);
                let [[sxx, sxy], [_, syy]] = ekf.position_covariance();
                let det = sxx * syy - sxy * sxy;
                let d2 = (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det;
                checks += 1;
                inside += u32::from(d2 <= THREE_SIGMA_2DOF);
            }
        }
        let fraction = f64::from(inside) / f64::from(checks);
        assert!(fraction >= 0.99, "seed {seed}: {fraction} inside 3σ");
        assert!(
            outliers > 50,
            "seed {seed}: the run had outliers ({outliers})"
        );
        assert_eq!(
            rejected_outliers, outliers,
            "seed {seed}: every outlier rejected"
        );
        assert!(
            rejected_inliers * 100 < checks,
            "seed {seed}: {rejected_inliers} good fixes lost"
        );
        let p = ekf.pose();
        let t = truth.pose;
        assert!(
            (p.x - t.x).hypot(p.y - t.y) < 1.0,
            "seed {seed}: {p:?} vs {t:?}"
        );
    }
}

#[test]
fn heading_updates_wrap_and_bad_input_changes_nothing() {
    let mut ekf = Ekf::new(
        Pose {
            x: 0.0,
            y: 0.0,
            yaw: 3.1,
        },
        1.0,
        0.1,
        ProcessNoise::default(),
    );
    // −3.1 is 0.083 rad from 3.1 across ±π, not 6.2.
    assert!(matches!(
        ekf.update_heading(-3.1, 0.05),
        Update::Accepted(_)
    ));
    assert!(ekf.pose().yaw.abs() > 3.1);
    let before = ekf.clone();
    ekf.predict(f64::NAN);
    ekf.predict(-1.0);
    assert_eq!(ekf, before);
    assert!(matches!(
        ekf.update_gnss(f64::NAN, 0.0, 1.0),
        Update::Rejected(_)
    ));
    assert_eq!(ekf, before);
}
