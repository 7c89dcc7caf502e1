//! ROS 2 over DDS, in pure Rust and without a ROS installation.
//!
//! - [`msg`]: the messages (ros2_socketcan's frames, Autoware's control and vehicle messages,
//!   `Twist`, `JointState`) as serde structs in CDR order, with their ROS 2 type names.
//! - [`autoware_vehicle`]: Autoware's commands into a profile's vehicle command (through the
//!   4WS geometry), the vehicle's feedback into Autoware's reports.
//! - [`frames`]: CAN frames as ros2_socketcan's messages, both ways, checked.
//! - `dds` (feature `dds`): a ROS 2 node on RustDDS (domain, namespace, interfaces, QoS), and
//!   on it `can_bridge` (ros2_socketcan's topics for any bus bywire opens) and
//!   `control_output` (Autoware's `Control` out as the `autoware-can` frames and/or DDS) and
//!   `vehicle_interface` (the Autoware vehicle interface for any profile).
//! - `simulation` (feature `sim`): the simulated tug driven over ROS 2.
//! - `canopen_bridge` (feature `canopen`): CiA 402 drives on ROS 2, as ros2_canopen offers them.
//!
//! Autoware steers a bicycle; the reference tug steers all four wheels in counter-phase. The
//! same path is the front wheels at atan(tan δ / 2), and back again:
//!
//! ```
//! use bywire_ros::autoware_vehicle::{steering_command, tire_angle, Geometry};
//! use bywire_vehicle::command::SteeringMode;
//!
//! let tug = Geometry { wheelbase: 3.2, track: 1.8, wheel_diameter: 0.5, four_wheel_steer: true };
//! let front_deg = steering_command(0.3, SteeringMode::Normal, &tug);
//! assert!((front_deg - (0.3f64.tan() / 2.0).atan().to_degrees()).abs() < 1e-9);
//! assert!((tire_angle(front_deg, SteeringMode::Normal, &tug) - 0.3).abs() < 1e-12);
//! ```

pub mod autoware_vehicle;
pub mod frames;
pub mod msg;

#[cfg(feature = "dds")]
pub mod can_bridge;
#[cfg(feature = "canopen")]
pub mod canopen_bridge;
#[cfg(feature = "dds")]
pub mod control_output;
#[cfg(feature = "dds")]
pub mod dds;
#[cfg(feature = "sim")]
pub mod simulation;
#[cfg(feature = "dds")]
pub mod vehicle_interface;
