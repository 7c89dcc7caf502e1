//! The tug's smaller nodes, each the same sans-IO shape as the ECU: the safety controller
//! (E-stop chain frames on bus 1), the BMS (battery on bus 1), the IMU and the I/O node (hub
//! encoders and the steering sensors' second tracks on bus 3). Each sends on a fixed period
//! what it was last given to measure: the simulator hands them the plant's readings as values
//! just before they are due ([`Periodic::due_within`]).

use core::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};
use bywire_tug::messages::{
    self, Battery as BatteryMessage, EmergencyStop, Imu, SteeringAngleSensors, SteeringAnglesB,
    SteeringAnglesC, WheelEncoders,
};

/// A fixed send period and the 4-bit rolling counter every reference-tug message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Periodic {
    period: Duration,
    next: Timestamp,
    counter: u64,
}

impl Periodic {
    /// Every `period`, from time zero.
    pub fn new(period: Duration) -> Self {
        Periodic {
            period,
            next: Timestamp::ZERO,
            counter: 0,
        }
    }

    /// Whether the next send falls before `until` (its readings are wanted now).
    pub fn due_within(&self, until: Timestamp) -> bool {
        self.next < until
    }

    /// The counter to send at `now`, if a send is due (and the schedule moves on).
    fn take(&mut self, now: Timestamp) -> Option<u64> {
        if now < self.next {
            return None;
        }
        self.next = now.saturating_add(self.period);
        let counter = self.counter & 0x0F;
        self.counter = self.counter.wrapping_add(1);
        Some(counter)
    }
}

/// A node that sends one reading's frames on its period.
pub struct Sender<R> {
    /// The schedule.
    pub schedule: Periodic,
    /// What it measures now.
    pub reading: R,
    encode: fn(&R, u64, &mut dyn FnMut(Frame)),
}

impl<R> Sender<R> {
    fn new(period: Duration, reading: R, encode: fn(&R, u64, &mut dyn FnMut(Frame))) -> Self {
        Sender {
            schedule: Periodic::new(period),
            reading,
            encode,
        }
    }
}

impl<R> Node for Sender<R> {
    // They listen to nothing.
    fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if let Some(counter) = self.schedule.take(now) {
            (self.encode)(&self.reading, counter, &mut |frame| out(Port::MAIN, frame));
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        Some(self.schedule.next)
    }
}

/// The safety controller: the E-stop chain's state (`true`: open) every 20 ms.
pub type SafetyController = Sender<bool>;

/// A safety controller whose chain is closed.
pub fn safety_controller() -> SafetyController {
    Sender::new(Duration::from_millis(20), false, |open, counter, out| {
        let mut m = EmergencyStop::default();
        m.set_estop_request_raw(u64::from(*open));
        m.set_counter_raw(counter);
        out(messages::sealed_frame(EmergencyStop::ID, m.0));
    })
}

/// What the BMS measures.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BatteryReading {
    /// Terminal voltage, V.
    pub voltage: f64,
    /// Current, A (positive discharging).
    pub current: f64,
    /// State of charge, 0–1.
    pub soc: f64,
}

/// The BMS: the battery every 100 ms.
pub type Bms = Sender<BatteryReading>;

/// A BMS with nothing measured yet.
pub fn bms() -> Bms {
    Sender::new(
        Duration::from_millis(100),
        BatteryReading::default(),
        |r, counter, out| {
            let mut m = BatteryMessage::default();
            let _ = m.set_battery_voltage(r.voltage.clamp(0.0, 120.0));
            let _ = m.set_battery_current(r.current.clamp(-1000.0, 1000.0));
            let _ = m.set_state_of_charge((r.soc * 100.0).clamp(0.0, 100.0));
            m.set_counter_raw(counter);
            out(messages::sealed_frame(BatteryMessage::ID, m.0));
        },
    )
}

/// What the IMU measures: yaw rate (degrees/s) and longitudinal acceleration (m/s²).
pub type ImuReading = (f64, f64);

/// The IMU on bus 3, every 10 ms.
pub type ImuNode = Sender<ImuReading>;

/// An IMU at rest.
pub fn imu() -> ImuNode {
    Sender::new(
        Duration::from_millis(10),
        (0.0, 0.0),
        |(yaw_rate, accel), counter, out| {
            let mut m = Imu::default();
            let _ = m.set_yaw_rate(yaw_rate.clamp(-327.0, 327.0));
            let _ = m.set_accel_x(accel.clamp(-32.0, 32.0));
            m.set_counter_raw(counter);
            out(messages::sealed_frame(Imu::ID, m.0));
        },
    )
}

/// What an angle-sensor module measures: each corner's angle (degrees), FL, FR, RL, RR
/// (`None`: no reading).
pub type AngleReading = [Option<f64>; 4];

/// One of the redundant tug's angle-sensor modules (B or C) on bus 3, every 10 ms.
pub type AngleModule = Sender<AngleReading>;

/// The raw value a module sends for a corner without a reading (the signal's minimum).
const NO_READING: u64 = 0x800;

/// Module `B` (0) or `C` (1), nothing measured yet.
pub fn angle_module(module: usize) -> AngleModule {
    fn encode<const ID: u32>(r: &AngleReading, counter: u64, out: &mut dyn FnMut(Frame)) {
        let mut m = SteeringAnglesB::default();
        let [fl, fr, rl, rr] = *r;
        let raw = |angle: Option<f64>| {
            angle.map_or(NO_READING, |a| {
                // 0.1 degree a count, 12 bits, two's complement.
                let counts = bywire_core::num::round_to_i32(a.clamp(-204.7, 204.7) * 10.0);
                u64::from(counts.cast_unsigned()) & 0xFFF
            })
        };
        m.set_angle_fl_raw(raw(fl));
        m.set_angle_fr_raw(raw(fr));
        m.set_angle_rl_raw(raw(rl));
        m.set_angle_rr_raw(raw(rr));
        m.set_counter_raw(counter);
        out(messages::sealed_frame(ID, m.0));
    }
    let encode = if module == 0 {
        encode::<{ SteeringAnglesB::ID }>
    } else {
        encode::<{ SteeringAnglesC::ID }>
    };
    Sender::new(Duration::from_millis(10), [None; 4], encode)
}

/// What the I/O node measures: the hub encoders' speeds (m/s) and the steering sensors'
/// second tracks (degrees), FL, FR, RL, RR.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct IoReading {
    /// Hub encoder speeds.
    pub encoders: [f64; 4],
    /// Second tracks.
    pub second_tracks: [f64; 4],
}

/// The I/O node on bus 3, every 10 ms.
pub type IoNode = Sender<IoReading>;

/// An I/O node with nothing measured yet.
pub fn io_node() -> IoNode {
    Sender::new(
        Duration::from_millis(10),
        IoReading::default(),
        |r, counter, out| {
            let mut encoders = WheelEncoders::default();
            let [fl, fr, rl, rr] = r.encoders.map(|v| v.clamp(-20.0, 20.0));
            let _ = (
                encoders.set_encoder_speed_fl(fl),
                encoders.set_encoder_speed_fr(fr),
                encoders.set_encoder_speed_rl(rl),
                encoders.set_encoder_speed_rr(rr),
            );
            encoders.set_counter_raw(counter);
            let mut second = SteeringAngleSensors::default();
            let [fl, fr, rl, rr] = r.second_tracks.map(|a| a.clamp(-200.0, 200.0));
            let _ = (
                second.set_second_angle_fl(fl),
                second.set_second_angle_fr(fr),
                second.set_second_angle_rl(rl),
                second.set_second_angle_rr(rr),
            );
            second.set_counter_raw(counter);
            out(messages::sealed_frame(WheelEncoders::ID, encoders.0));
            out(messages::sealed_frame(SteeringAngleSensors::ID, second.0));
        },
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;

    #[test]
    fn a_sender_sends_on_its_period_with_a_rolling_counter() {
        let mut safety = safety_controller();
        let mut sent = Vec::new();
        for ms in 0..400u64 {
            let now = Timestamp::from_millis(ms);
            if safety.next_deadline().is_some_and(|d| d <= now) {
                safety.reading = ms >= 200;
                safety.poll(now, &mut |_, f| sent.push((ms, f)));
            }
        }
        assert_eq!(sent.len(), 20);
        assert!(sent.iter().all(|(ms, _)| ms % 20 == 0));
        let payloads: Vec<[u8; 8]> = sent
            .iter()
            .map(|(_, f)| messages::payload(f).unwrap())
            .collect();
        for (k, p) in payloads.iter().enumerate() {
            assert!(messages::is_sealed(EmergencyStop::ID, p));
            let m = EmergencyStop(*p);
            assert_eq!(m.counter_raw(), (k as u64) & 0x0F);
            assert_eq!(m.estop_request_raw(), u64::from(k >= 10));
        }
    }
}
