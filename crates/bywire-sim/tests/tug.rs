//! The simulated tug drives a route over its buses: the ADS engages the vehicle control ECU
//! on bus 1, the ECU walks eight CiA 402 drives to Operation enabled on bus 2, and the plants
//! carry the tug along the route.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_control::kinematics::Point;
use bywire_sim::tug::{Tug, TugParams};
use bywire_vehicle::reference_tug::ControlMode;

fn route() -> Vec<Point> {
    // 30 m straight, a quarter circle of 15 m radius to the left, 20 m straight.
    let mut points: Vec<Point> = (0..=30)
        .map(|x| Point {
            x: f64::from(x),
            y: 0.0,
        })
        .collect();
    for k in 1..=20 {
        let a = f64::from(k) / 20.0 * std::f64::consts::FRAC_PI_2;
        points.push(Point {
            x: 30.0 + 15.0 * a.sin(),
            y: 15.0 - 15.0 * a.cos(),
        });
    }
    for y in 1..=20 {
        points.push(Point {
            x: 45.0,
            y: 15.0 + f64::from(y),
        });
    }
    points
}

fn run(seed: u64) -> Tug {
    let mut tug = Tug::new(TugParams {
        seed,
        payload: 2_000.0,
        grade: 0.0,
        route: route(),
        speed: 3.0,
    });
    for _ in 0..60_000 {
        tug.step();
        if tug.remaining() < 0.5 && tug.now().as_nanos() > 5_000_000_000 {
            break;
        }
    }
    tug
}

#[test]
fn the_tug_follows_its_route_over_its_buses() {
    let tug = run(1);
    let pose = tug.pose();
    assert_eq!(
        tug.ecu().mode(),
        ControlMode::Autonomous,
        "engaged over bus 1"
    );
    assert!(
        tug.remaining() < 1.0,
        "reached the end: {} m left at {:?}, pose {pose:?}",
        tug.remaining(),
        tug.now()
    );
    // 73 m at up to 3 m/s with the start and the stop: under 40 s.
    assert!(tug.now().as_nanos() < 40_000_000_000, "{:?}", tug.now());
    let worst = tug.tracking_errors.iter().cloned().fold(0.0, f64::max);
    let mean = tug.tracking_errors.iter().sum::<f64>() / tug.tracking_errors.len() as f64;
    assert!(
        worst < 0.5 && mean < 0.2,
        "tracking error: worst {worst} m, mean {mean} m"
    );
    // Commands and state at 50 Hz on 500 kbit/s; eight drives' PDOs and heartbeats on 1 Mbit/s.
    let (load1, load2) = tug.bus_loads();
    assert!(
        (0.01..0.1).contains(&load1) && (0.1..0.5).contains(&load2),
        "bus loads {load1} {load2}"
    );
    assert!(tug.soc() < 0.8, "the battery drove it");
}

#[test]
fn the_same_seed_gives_the_same_frames() {
    let (a, b) = (run(7), run(7));
    assert_eq!(a.bus1_log, b.bus1_log);
    assert_eq!(a.bus2_log, b.bus2_log);
    assert_eq!(a.pose(), b.pose());
}
