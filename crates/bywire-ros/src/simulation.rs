//! The simulated tug as an Autoware vehicle: its ADS slot on bus 1 and 1b taken by the
//! vehicle interface ([`VehicleInterface`]), so whatever publishes `control_cmd` drives it,
//! in real time (simulated time paced to the clock). Its reports are the interface's, plus its
//! true pose as `nav_msgs/Odometry` on Autoware's `/localization/kinematic_state`.

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use bywire_bus::runner::{Flow, Hooks};
use bywire_core::Timestamp;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::Tug;

use crate::dds::{reliable, RosError, RosNode};
use crate::msg::{
    Header, Odometry, Point, Pose, PoseWithCovariance, Quaternion, Time, Twist,
    TwistWithCovariance, Vector3,
};
use crate::vehicle_interface::{VehicleEvent, VehicleInterface, VehicleInterfaceConfig};

/// How often (simulated) the interface takes its inputs and may report.
const INTERFACE_PERIOD: Duration = Duration::from_millis(2);

/// How a simulated run over ROS 2 goes.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationConfig {
    /// The vehicle interface's topics and rates.
    pub interface: VehicleInterfaceConfig,
    /// Where the true pose goes.
    pub odometry: String,
    /// End after this much simulated time.
    pub limit: Duration,
}

impl Default for SimulationConfig {
    fn default() -> Self {
        SimulationConfig {
            interface: VehicleInterfaceConfig::default(),
            odometry: "/localization/kinematic_state".into(),
            limit: Duration::from_secs(300),
        }
    }
}

fn odometry(tug: &Tug, yaw_rate: f64, stamp: Time) -> Odometry {
    let pose = tug.pose();
    Odometry {
        header: Header {
            stamp,
            frame_id: "map".into(),
        },
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point {
                    x: pose.x,
                    y: pose.y,
                    z: 0.0,
                },
                orientation: Quaternion::from_yaw(pose.yaw),
            },
            ..PoseWithCovariance::default()
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3 {
                    x: tug.pose_speed(),
                    ..Vector3::default()
                },
                angular: Vector3 {
                    z: yaw_rate,
                    ..Vector3::default()
                },
            },
            ..TwistWithCovariance::default()
        },
    }
}

/// Run `tug` (with `scenario`'s faults) driven over ROS 2 until `stop` (then the interface
/// brakes for a second) or the time limit. `tick` is called after every interface pass (for
/// progress lines, shared buses); its error ends the run. Returns the simulated time reached.
pub fn run(
    node: &mut RosNode,
    tug: &mut Tug,
    scenario: &Scenario,
    config: &SimulationConfig,
    stop: &AtomicBool,
    report: &mut dyn FnMut(VehicleEvent),
    tick: &mut dyn FnMut(&mut Tug) -> Result<(), String>,
) -> Result<Timestamp, RosError> {
    let profile =
        bywire_tug::builtin("reference-tug").map_err(|e| RosError::Create(e.to_string()))?;
    let odometry_out = node.publisher::<Odometry>(&config.odometry, &reliable(1))?;
    // The tug's plain variant (the secured one's key is the simulation's own).
    let wire = bywire_vehicle::wire::ProfileWire::new(&profile)
        .map_err(|e| RosError::Create(e.to_string()))?;
    let (mut interface, mut ads) = VehicleInterface::new(
        node,
        &profile,
        bywire_vehicle::secured::Secured::plain(wire),
        true,
        &config.interface,
        stop,
        report,
    )?;
    let limit = Timestamp::ZERO.saturating_add(config.limit);
    let start = Instant::now();
    let mut next_pass = Timestamp::ZERO;
    let mut next_pose = Timestamp::ZERO;
    let mut last_yaw: Option<(Timestamp, f64)> = None;
    loop {
        scenario.step_with_ads(tug, &mut ads);
        let now = tug.now();
        if now >= limit {
            return Ok(now);
        }
        if now < next_pass {
            continue;
        }
        next_pass = now.saturating_add(INTERFACE_PERIOD);
        if interface.after_poll(&mut ads, now) == Flow::Stop {
            return Ok(now);
        }
        if now >= next_pose {
            next_pose = now.saturating_add(config.interface.report_period);
            let yaw = tug.pose().yaw;
            let yaw_rate = last_yaw.map_or(0.0, |(at, previous)| {
                let dt = now.saturating_since(at).as_secs_f64();
                let turned = libm::remainder(yaw - previous, core::f64::consts::TAU);
                if dt > 0.0 {
                    turned / dt
                } else {
                    0.0
                }
            });
            last_yaw = Some((now, yaw));
            let _ = odometry_out.publish(odometry(tug, yaw_rate, Time::now()));
        }
        tick(tug).map_err(RosError::Create)?;
        // Real time: the simulation never runs ahead of the clock.
        let ahead = Duration::from_nanos(now.as_nanos()).saturating_sub(start.elapsed());
        if !ahead.is_zero() {
            std::thread::sleep(ahead);
        }
    }
}
