//! Step-response metrics from a recorded response: rise time (10–90 %), settling time (2 % and
//! 5 % bands), overshoot, steady-state error, and the error integrals IAE, ISE and ITAE.
//!
//! Times are relative to the first sample. The final value is the last sample; bands and
//! overshoot are relative to the step from `initial` to that final value, as in the classic
//! definitions, and the steady-state error is `setpoint − final`.

/// Why a response could not be measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum MetricsError {
    /// Times and values differ in length.
    LengthMismatch,
    /// Fewer than two samples.
    TooShort,
    /// Sample `index` is not finite, or its time does not increase.
    BadSample {
        /// Which sample.
        index: usize,
    },
    /// The response never moves away from its initial value.
    NoStep,
}

impl core::fmt::Display for MetricsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MetricsError::LengthMismatch => f.write_str("times and values differ in length"),
            MetricsError::TooShort => f.write_str("fewer than two samples"),
            MetricsError::BadSample { index } => {
                write!(
                    f,
                    "sample {index} is not finite or its time does not increase"
                )
            }
            MetricsError::NoStep => f.write_str("the response has no step to measure"),
        }
    }
}

/// The metrics of one step response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// From 10 % to 90 % of the step, s (`None` if 90 % is never reached).
    pub rise_time: Option<f64>,
    /// When the response last enters the ±2 % band for good, s.
    pub settling_time_2: f64,
    /// The same for ±5 %, s.
    pub settling_time_5: f64,
    /// Peak beyond the final value, % of the step (0 without overshoot).
    pub overshoot_percent: f64,
    /// Time of the peak, s.
    pub peak_time: f64,
    /// `setpoint − final value`.
    pub steady_state_error: f64,
    /// ∫|e| dt.
    pub iae: f64,
    /// ∫e² dt.
    pub ise: f64,
    /// ∫t·|e| dt.
    pub itae: f64,
}

/// Time at which the segment from (t0, y0) to (t1, y1) crosses `level` (linear interpolation).
fn crossing(t0: f64, y0: f64, t1: f64, y1: f64, level: f64) -> f64 {
    if y1 == y0 {
        t1
    } else {
        t0 + (t1 - t0) * (level - y0) / (y1 - y0)
    }
}

/// Measure a step response `y(t)` from `initial` towards `setpoint`.
pub fn step_metrics(
    times: &[f64],
    values: &[f64],
    initial: f64,
    setpoint: f64,
) -> Result<StepMetrics, MetricsError> {
    if times.len() != values.len() {
        return Err(MetricsError::LengthMismatch);
    }
    let (Some(&t_start), Some(&last)) = (times.first(), values.last()) else {
        return Err(MetricsError::TooShort);
    };
    if times.len() < 2 {
        return Err(MetricsError::TooShort);
    }
    for (index, pair) in times.windows(2).enumerate() {
        if let [a, b] = pair {
            if !(b > a && a.is_finite() && b.is_finite()) {
                return Err(MetricsError::BadSample { index: index + 1 });
            }
        }
    }
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(MetricsError::BadSample { index });
    }
    if !(initial.is_finite() && setpoint.is_finite()) {
        return Err(MetricsError::BadSample { index: 0 });
    }
    let step = last - initial;
    if step == 0.0 {
        return Err(MetricsError::NoStep);
    }
    // Progress of the step, 0 at the initial value and 1 at the final one.
    let progress = |y: f64| (y - initial) / step;
    let mut rise_start = None;
    let mut rise_end = None;
    let mut peak = (f64::NEG_INFINITY, t_start);
    let mut outside_2 = None::<f64>;
    let mut outside_5 = None::<f64>;
    let (mut iae, mut ise, mut itae) = (0.0, 0.0, 0.0);
    let mut previous: Option<(f64, f64)> = None;
    for (&t, &y) in times.iter().zip(values) {
        let p = progress(y);
        if p > peak.0 {
            peak = (p, t - t_start);
        }
        let deviation = (p - 1.0).abs();
        if deviation > 0.02 {
            outside_2 = Some(t);
        }
        if deviation > 0.05 {
            outside_5 = Some(t);
        }
        if let Some((t0, y0)) = previous {
            let p0 = progress(y0);
            if rise_start.is_none() && p0 < 0.1 && p >= 0.1 {
                rise_start = Some(crossing(t0, p0, t, p, 0.1));
            }
            if rise_end.is_none() && p0 < 0.9 && p >= 0.9 {
                rise_end = Some(crossing(t0, p0, t, p, 0.9));
            }
            // Trapezoids of the error integrals.
            let (e0, e1) = (setpoint - y0, setpoint - y);
            let dt = t - t0;
            iae += (e0.abs() + e1.abs()) / 2.0 * dt;
            ise += (e0 * e0 + e1 * e1) / 2.0 * dt;
            itae += ((t0 - t_start) * e0.abs() + (t - t_start) * e1.abs()) / 2.0 * dt;
        } else if p >= 0.1 {
            rise_start = Some(t);
        }
        previous = Some((t, y));
    }
    // Settled from the first sample after the last one outside the band.
    let settled = |outside: Option<f64>| {
        outside
            .and_then(|o| times.iter().find(|&&t| t > o))
            .map_or(0.0, |&t| t - t_start)
    };
    Ok(StepMetrics {
        rise_time: match (rise_start, rise_end) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        },
        settling_time_2: settled(outside_2),
        settling_time_5: settled(outside_5),
        overshoot_percent: ((peak.0 - 1.0) * 100.0).max(0.0),
        peak_time: peak.1,
        steady_state_error: setpoint - last,
        iae,
        ise,
        itae,
    })
}
