//! An extended Kalman filter for a ground vehicle: wheel odometry, IMU and GNSS fused into
//! position, heading, speed, yaw rate and acceleration, with covariances.
//!
//! State `[x, y, yaw, v, yaw_rate, accel]`: a constant-acceleration, constant-turn-rate model.
//! Each measurement update gates its innovation by Mahalanobis distance (χ² threshold) so that
//! an outlier — a GNSS multipath jump — is rejected and reported instead of pulling the
//! estimate. Fixed-size matrices on the stack: nothing allocates.

// Every index here is a constant within the dimensions of a fixed-size matrix (checked by the
// types), so none can panic; the alternatives (36-argument constructors) read worse.
#![allow(clippy::indexing_slicing)]

use nalgebra::{SMatrix, SVector};

use crate::kinematics::Pose;
use crate::math::{self, wrap_angle};

/// Number of states.
pub const STATES: usize = 6;
type Vector = SVector<f64, STATES>;
type Matrix = SMatrix<f64, STATES, STATES>;

const X: usize = 0;
const Y: usize = 1;
const YAW: usize = 2;
const V: usize = 3;
const YAW_RATE: usize = 4;
const ACCEL: usize = 5;

/// χ² thresholds at 99.9 %: innovations beyond are rejected.
pub const GATE_1DOF: f64 = 10.83;
/// For two degrees of freedom.
pub const GATE_2DOF: f64 = 13.82;

/// Process noise: how fast the model's unmodelled inputs wander (spectral densities).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Position, m²/s.
    pub position: f64,
    /// Heading, rad²/s.
    pub yaw: f64,
    /// Speed, (m/s)²/s.
    pub speed: f64,
    /// Yaw rate, (rad/s)²/s.
    pub yaw_rate: f64,
    /// Acceleration, (m/s²)²/s.
    pub accel: f64,
}

impl Default for ProcessNoise {
    /// Values for a slow vehicle (an apron tug, a few m/s).
    fn default() -> Self {
        ProcessNoise {
            position: 1e-4,
            yaw: 1e-5,
            speed: 0.05,
            yaw_rate: 0.01,
            accel: 0.5,
        }
    }
}

/// What an update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Update {
    /// Fused; the innovation's Mahalanobis distance squared.
    Accepted(f64),
    /// Rejected by the gate (or a singular or non-finite innovation); its distance squared.
    Rejected(f64),
}

/// The filter.
#[derive(Debug, Clone, PartialEq)]
pub struct Ekf {
    state: Vector,
    covariance: Matrix,
    noise: ProcessNoise,
}

impl Ekf {
    /// Start at `pose`, at rest, with standard deviations for the pose (m, rad) and the
    /// motion states.
    pub fn new(pose: Pose, position_sigma: f64, yaw_sigma: f64, noise: ProcessNoise) -> Self {
        let mut state = Vector::zeros();
        state[X] = pose.x;
        state[Y] = pose.y;
        state[YAW] = pose.yaw;
        let p = position_sigma * position_sigma;
        let covariance =
            Matrix::from_diagonal(&Vector::from([p, p, yaw_sigma * yaw_sigma, 1.0, 0.1, 1.0]));
        Ekf {
            state,
            covariance,
            noise,
        }
    }

    /// The estimated pose.
    pub fn pose(&self) -> Pose {
        Pose {
            x: self.state[X],
            y: self.state[Y],
            yaw: self.state[YAW],
        }
    }

    /// Speed, yaw rate and acceleration.
    pub fn motion(&self) -> (f64, f64, f64) {
        (self.state[V], self.state[YAW_RATE], self.state[ACCEL])
    }

    /// The full state `[x, y, yaw, v, yaw_rate, accel]`.
    pub fn state(&self) -> [f64; STATES] {
        self.state.into()
    }

    /// The state covariance.
    pub fn covariance(&self) -> [[f64; STATES]; STATES] {
        self.covariance.into()
    }

    /// The 2×2 position covariance, `[[σxx, σxy], [σxy, σyy]]`.
    pub fn position_covariance(&self) -> [[f64; 2]; 2] {
        let c = &self.covariance;
        [[c[(X, X)], c[(X, Y)]], [c[(Y, X)], c[(Y, Y)]]]
    }

    /// Advance the model `dt` seconds. Non-positive or non-finite `dt` does nothing.
    pub fn predict(&mut self, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        let s = self.state;
        let (yaw, v) = (s[YAW], s[V]);
        // Integrate at the mid-step heading and speed (second order in dt).
        let mid_yaw = yaw + s[YAW_RATE] * dt / 2.0;
        let mid_v = v + s[ACCEL] * dt / 2.0;
        let (sin, cos) = (math::sin(mid_yaw), math::cos(mid_yaw));
        let mut next = s;
        next[X] += mid_v * cos * dt;
        next[Y] += mid_v * sin * dt;
        next[YAW] = wrap_angle(yaw + s[YAW_RATE] * dt);
        next[V] += s[ACCEL] * dt;
        // Jacobian of the transition.
        let mut f = Matrix::identity();
        f[(X, YAW)] = -mid_v * sin * dt;
        f[(X, V)] = cos * dt;
        f[(X, YAW_RATE)] = -mid_v * sin * dt * dt / 2.0;
        f[(X, ACCEL)] = cos * dt * dt / 2.0;
        f[(Y, YAW)] = mid_v * cos * dt;
        f[(Y, V)] = sin * dt;
        f[(Y, YAW_RATE)] = mid_v * cos * dt * dt / 2.0;
        f[(Y, ACCEL)] = sin * dt * dt / 2.0;
        f[(YAW, YAW_RATE)] = dt;
        f[(V, ACCEL)] = dt;
        let n = self.noise;
        let q = Matrix::from_diagonal(&Vector::from([
            n.position * dt,
            n.position * dt,
            n.yaw * dt,
            n.speed * dt,
            n.yaw_rate * dt,
            n.accel * dt,
        ]));
        self.state = next;
        self.covariance = f * self.covariance * f.transpose() + q;
    }

    /// Fuse measurement `z` of `h·state` (linear in the state) with covariance `r`, gated at
    /// `gate` (χ² for M degrees of freedom). `angles` marks components that are angles (their
    /// innovation is wrapped).
    fn update<const M: usize>(
        &mut self,
        z: SVector<f64, M>,
        h: SMatrix<f64, M, STATES>,
        r: SMatrix<f64, M, M>,
        gate: f64,
        angles: [bool; M],
    ) -> Update {
        let mut innovation = z - h * self.state;
        for (value, is_angle) in innovation.iter_mut().zip(angles) {
            if is_angle {
                *value = wrap_angle(*value);
            }
        }
        let s = h * self.covariance * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return Update::Rejected(f64::INFINITY);
        };
        let d2 = (innovation.transpose() * s_inv * innovation)[(0, 0)];
        if !(d2.is_finite() && d2 <= gate) {
            return Update::Rejected(d2);
        }
        let k = self.covariance * h.transpose() * s_inv;
        self.state += k * innovation;
        self.state[YAW] = wrap_angle(self.state[YAW]);
        // Joseph form: stays symmetric and positive semi-definite.
        let i_kh = Matrix::identity() - k * h;
        self.covariance = i_kh * self.covariance * i_kh.transpose() + k * r * k.transpose();
        Update::Accepted(d2)
    }

    /// Two states measured directly, with independent noise.
    fn update_direct(&mut self, states: [usize; 2], z: [f64; 2], sigmas: (f64, f64)) -> Update {
        let mut h = SMatrix::<f64, 2, STATES>::zeros();
        h[(0, states[0])] = 1.0;
        h[(1, states[1])] = 1.0;
        let r = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from([
            sigmas.0 * sigmas.0,
            sigmas.1 * sigmas.1,
        ]));
        self.update(SVector::from(z), h, r, GATE_2DOF, [false; 2])
    }

    /// Wheel odometry: speed (m/s) and yaw rate (rad/s) with their standard deviations.
    pub fn update_odometry(&mut self, speed: f64, yaw_rate: f64, sigmas: (f64, f64)) -> Update {
        self.update_direct([V, YAW_RATE], [speed, yaw_rate], sigmas)
    }

    /// IMU: yaw rate (rad/s) and longitudinal acceleration (m/s²) with their standard
    /// deviations.
    pub fn update_imu(&mut self, yaw_rate: f64, accel: f64, sigmas: (f64, f64)) -> Update {
        self.update_direct([YAW_RATE, ACCEL], [yaw_rate, accel], sigmas)
    }

    /// GNSS position (m, in the filter's frame) with its standard deviation.
    pub fn update_gnss(&mut self, x: f64, y: f64, sigma: f64) -> Update {
        self.update_direct([X, Y], [x, y], (sigma, sigma))
    }

    /// A heading measurement (a dual-antenna GNSS, a compass), rad.
    pub fn update_heading(&mut self, yaw: f64, sigma: f64) -> Update {
        let mut h = SMatrix::<f64, 1, STATES>::zeros();
        h[(0, YAW)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(sigma * sigma);
        self.update(SVector::from([yaw]), h, r, GATE_1DOF, [true])
    }
}
