//! The traction battery: an 88 V pack with its capacity, state of charge, open-circuit voltage
//! rising with charge, and internal resistance that makes the voltage sag under load.

/// Pack parameters (defaults: the tug's 88 V lithium pack).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryParams {
    /// Capacity, ampere-hours.
    pub capacity_ah: f64,
    /// Open-circuit voltage when empty, V.
    pub empty_v: f64,
    /// Open-circuit voltage when full, V.
    pub full_v: f64,
    /// Internal resistance, Ω.
    pub resistance: f64,
}

impl Default for BatteryParams {
    fn default() -> Self {
        BatteryParams {
            capacity_ah: 400.0,
            empty_v: 80.0,
            full_v: 96.0,
            resistance: 0.04,
        }
    }
}

/// The pack's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Battery {
    /// Parameters.
    pub params: BatteryParams,
    soc: f64,
    current: f64,
    voltage: f64,
}

impl Battery {
    /// A pack at `soc` (0–1).
    pub fn new(params: BatteryParams, soc: f64) -> Battery {
        let soc = soc.clamp(0.0, 1.0);
        let voltage = params.empty_v + (params.full_v - params.empty_v) * soc;
        Battery {
            params,
            soc,
            current: 0.0,
            voltage,
        }
    }

    /// State of charge, 0–1.
    pub fn soc(&self) -> f64 {
        self.soc
    }

    /// Open-circuit voltage at the present charge, V.
    pub fn open_circuit_v(&self) -> f64 {
        self.params.empty_v + (self.params.full_v - self.params.empty_v) * self.soc
    }

    /// Terminal voltage during the last step, V.
    pub fn terminal_v(&self) -> f64 {
        self.voltage
    }

    /// The present current, A (discharge positive, regeneration negative).
    pub fn current(&self) -> f64 {
        self.current
    }

    /// Draw `power` watts (negative: regenerate) for `dt` seconds; the current solves
    /// `P = (Voc − I·R)·I` (the smaller root; limited to what the pack can give).
    pub fn step(&mut self, dt: f64, power: f64) {
        let (voc, r) = (self.open_circuit_v(), self.params.resistance.max(1e-9));
        let discriminant = (voc * voc - 4.0 * r * power).max(0.0);
        self.current = (voc - libm::sqrt(discriminant)) / (2.0 * r);
        self.voltage = voc - self.current * r;
        self.soc =
            (self.soc - self.current * dt / 3600.0 / self.params.capacity_ah).clamp(0.0, 1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charge_falls_with_the_ampere_hours_drawn_and_the_voltage_sags() {
        let mut battery = Battery::new(BatteryParams::default(), 0.8);
        assert!((battery.open_circuit_v() - 92.8).abs() < 1e-9);
        // 20 kW for ten minutes.
        for _ in 0..600 {
            battery.step(1.0, 20_000.0);
        }
        let current = battery.current();
        // P = V·I at the terminal.
        assert!((battery.terminal_v() * current - 20_000.0).abs() < 1e-6);
        assert!(battery.terminal_v() < battery.open_circuit_v());
        // About 220 A for 1/6 h out of 400 Ah: about 9 % of the charge.
        assert!(
            (0.8 - battery.soc() - current / 6.0 / 400.0).abs() < 0.002,
            "{}",
            battery.soc()
        );
        // Regeneration charges it, and the terminal voltage rises above open circuit.
        let before = battery.soc();
        battery.step(60.0, -10_000.0);
        assert!(battery.soc() > before && battery.terminal_v() > battery.open_circuit_v());
    }
}
