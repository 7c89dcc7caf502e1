//! The reference tug's wire through the structs generated from its DBC: what an ECU build uses
//! (`no_std`, no allocation). For the same commands and states it makes the same bytes as
//! [`bywire_vehicle::wire::ProfileWire`] over the tug's profile (property-tested).

use bywire_core::{Frame, Id};
use bywire_vehicle::command::{
    ControlCommand, ControlMode, EstopCode, Gear, SteeringMode, WatchdogLevel,
};
use bywire_vehicle::wire::{
    AdsWire, Counters, DegradationReport, Feedback, Incoming, Rejected, StateFeedback, StateReport,
    VehicleWire,
};

use crate::messages::{
    self, AdsToVehicleControl, EmergencyBrake, EmergencyStop, VehicleToAdsDegradation,
    VehicleToAdsSensors, VehicleToAdsState, VehicleToAdsWheelAngles,
};

/// The reference tug, through its generated structs.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReferenceWire;

impl Counters for ReferenceWire {
    fn command_counter_bits(&self) -> u8 {
        4
    }

    fn state_counter_bits(&self) -> u8 {
        4
    }
}

impl AdsWire for ReferenceWire {
    fn wheel_counter_bits(&self) -> u8 {
        4
    }

    fn command_frame(&mut self, command: &ControlCommand, counter: u64) -> Option<Frame> {
        let m = messages::command_message(command, u8::try_from(counter & 0x0F).unwrap_or(0))?;
        Some(messages::sealed_frame(AdsToVehicleControl::ID, m.0))
    }

    fn emergency_brake_frame(&mut self, deceleration: f64, counter: u64) -> Option<Frame> {
        let mut m = EmergencyBrake::default();
        m.set_brake_request_raw(1);
        let _ = m.set_deceleration(deceleration.clamp(0.0, 25.5));
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(EmergencyBrake::ID, m.0))
    }

    fn feedback(&mut self, frame: &Frame) -> Feedback {
        let Some(Id::Standard(id)) = frame.id() else {
            return Feedback::Other;
        };
        let id = u32::from(id.as_raw());
        if ![
            VehicleToAdsState::ID,
            VehicleToAdsSensors::ID,
            VehicleToAdsWheelAngles::ID,
            VehicleToAdsDegradation::ID,
        ]
        .contains(&id)
        {
            return Feedback::Other;
        }
        let Some(payload) = messages::payload(frame).filter(|p| messages::is_sealed(id, p)) else {
            return Feedback::Corrupt;
        };
        match id {
            VehicleToAdsState::ID => {
                let m = VehicleToAdsState(payload);
                let (steering, velocity) = (m.steering_angle_actual(), m.velocity_actual());
                Feedback::State(StateFeedback {
                    counter: m.counter_raw(),
                    steering,
                    velocity,
                    mode: ControlMode::from_raw(m.control_mode_raw()).unwrap_or_default(),
                    watchdog_level: WatchdogLevel::from_raw(m.watchdog_level_raw()),
                    estop_state: EstopCode::from_raw(m.estop_state_raw()),
                    warning: Some(m.warning_flag_raw() == 1),
                    driver_override: Some(m.driver_override_raw() == 1),
                    gear: Gear::from_raw(m.gear_raw()),
                    steering_mode: SteeringMode::from_raw(m.steering_mode_raw()),
                    // The tug's state message has no lights.
                    turn_indicators: None,
                    hazard_lights: None,
                    heartbeat_echo: m.heartbeat_echo_raw(),
                    in_range: steering.abs() <= 45.0
                        && (-5.0..=8.0).contains(&velocity)
                        && m.watchdog_level_raw() <= 4,
                })
            }
            VehicleToAdsWheelAngles::ID => {
                let m = VehicleToAdsWheelAngles(payload);
                Feedback::WheelAngles {
                    counter: m.counter_raw(),
                    angles: [
                        m.wheel_angle_fl(),
                        m.wheel_angle_fr(),
                        m.wheel_angle_rl(),
                        m.wheel_angle_rr(),
                    ],
                }
            }
            VehicleToAdsDegradation::ID => {
                let m = VehicleToAdsDegradation(payload);
                // A level or reason that names nothing: not to be read.
                DegradationReport::from_raw(m.degradation_level_raw(), m.degradation_reason_raw())
                    .map_or(Feedback::Corrupt, Feedback::Degradation)
            }
            _ => {
                let m = VehicleToAdsSensors(payload);
                Feedback::WheelSpeeds {
                    counter: m.counter_raw(),
                    speeds: [
                        m.wheel_speed_fl(),
                        m.wheel_speed_fr(),
                        m.wheel_speed_rl(),
                        m.wheel_speed_rr(),
                    ],
                }
            }
        }
    }
}

impl VehicleWire for ReferenceWire {
    fn is_command(&self, id: Id) -> bool {
        !id.is_extended() && id.as_raw() == AdsToVehicleControl::ID
    }

    fn incoming(&mut self, frame: &Frame) -> Incoming {
        let Some(Id::Standard(id)) = frame.id() else {
            return Incoming::Other;
        };
        let id = u32::from(id.as_raw());
        let sealed = || messages::payload(frame).filter(|p| messages::is_sealed(id, p));
        match id {
            AdsToVehicleControl::ID => Incoming::Command(match messages::payload(frame) {
                None => Err(Rejected::Malformed),
                Some(p) if !messages::is_sealed(id, &p) => Err(Rejected::Checksum),
                Some(p) => {
                    let m = AdsToVehicleControl(p);
                    Ok((messages::command_of(&m), m.heartbeat_counter_raw()))
                }
            }),
            EmergencyStop::ID => sealed().map_or(Incoming::Other, |p| {
                Incoming::Estop(EmergencyStop(p).estop_request_raw() == 1)
            }),
            EmergencyBrake::ID => sealed().map_or(Incoming::Other, |p| {
                Incoming::EmergencyBrake(EmergencyBrake(p).brake_request_raw() == 1)
            }),
            _ => Incoming::Other,
        }
    }

    fn state_frame(&mut self, r: &StateReport, counter: u64) -> Option<Frame> {
        let mut m = VehicleToAdsState::default();
        // Out-of-range actuals are reported at their limit rather than dropped.
        let _ = m.set_steering_angle_actual(r.steering.clamp(-45.0, 45.0));
        let _ = m.set_velocity_actual(r.velocity.clamp(-5.0, 8.0));
        m.set_control_mode_raw(r.mode as u64);
        m.set_steering_mode_raw(r.steering_mode as u64);
        m.set_gear_raw(r.gear as u64);
        m.set_watchdog_level_raw(r.watchdog_level.raw());
        m.set_estop_state_raw(r.estop_state.raw());
        m.set_warning_flag_raw(u64::from(r.warning));
        m.set_driver_override_raw(u64::from(r.driver_override));
        m.set_steering_enabled_raw(u64::from(r.steering_enabled));
        m.set_heartbeat_echo_raw(r.heartbeat_echo);
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(VehicleToAdsState::ID, m.0))
    }

    fn wheel_speeds_frame(&mut self, speeds: [f64; 4], counter: u64) -> Option<Frame> {
        let mut m = VehicleToAdsSensors::default();
        // Beyond the signals' declared range they are reported at its limit.
        let [fl, fr, rl, rr] = speeds.map(|v| v.clamp(-20.48, 20.47));
        let _ = (
            m.set_wheel_speed_fl(fl),
            m.set_wheel_speed_fr(fr),
            m.set_wheel_speed_rl(rl),
            m.set_wheel_speed_rr(rr),
        );
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(VehicleToAdsSensors::ID, m.0))
    }

    fn wheel_angles_frame(&mut self, angles: [f64; 4], counter: u64) -> Option<Frame> {
        let mut m = VehicleToAdsWheelAngles::default();
        // Beyond the signals' declared range they are reported at its limit.
        let [fl, fr, rl, rr] = angles.map(|a| a.clamp(-204.8, 204.7));
        let _ = (
            m.set_wheel_angle_fl(fl),
            m.set_wheel_angle_fr(fr),
            m.set_wheel_angle_rl(rl),
            m.set_wheel_angle_rr(rr),
        );
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(VehicleToAdsWheelAngles::ID, m.0))
    }

    fn degradation_frame(&mut self, report: &DegradationReport, counter: u64) -> Option<Frame> {
        let mut m = VehicleToAdsDegradation::default();
        m.set_degradation_level_raw(report.level.raw());
        m.set_degradation_reason_raw(report.reason_raw());
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(VehicleToAdsDegradation::ID, m.0))
    }
}
