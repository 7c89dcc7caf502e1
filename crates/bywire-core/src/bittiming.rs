//! Bit timing: prescaler and segments for a bitrate and sample point on a given controller.
//!
//! A bit is divided into time quanta (tq = BRP / clock): one for synchronisation, then PROP_SEG
//! and PHASE_SEG1 up to the sample point, then PHASE_SEG2. Controllers have a combined TSEG1
//! (PROP_SEG + PHASE_SEG1) register, limits on each field, and a prescaler step.
//!
//! [`calculate`] searches exactly as the Linux kernel's `can_calc_bittiming` does (same order,
//! same tie-breaks, same integer arithmetic in permille), so it gives the answer
//! `ip link set can0 type can bitrate B sample-point P` gives on that controller. It is
//! reimplemented rather than bound because the kernel is not there on an ECU or in a test.

/// Register limits of a CAN controller (the kernel's `struct can_bittiming_const`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Controller name.
    pub name: &'static str,
    /// TSEG1 (PROP_SEG + PHASE_SEG1) range in tq.
    pub tseg1: (u32, u32),
    /// TSEG2 (PHASE_SEG2) range in tq.
    pub tseg2: (u32, u32),
    /// Largest synchronisation jump width.
    pub sjw_max: u32,
    /// Prescaler range.
    pub brp: (u32, u32),
    /// Prescaler step.
    pub brp_inc: u32,
}

/// NXP SJA1000 (BTR0/BTR1): TSEG1 4 bits, TSEG2 3 bits, SJW 2 bits, BRP 6 bits.
pub const SJA1000: Limits = Limits {
    name: "sja1000",
    tseg1: (1, 16),
    tseg2: (1, 8),
    sjw_max: 4,
    brp: (1, 64),
    brp_inc: 1,
};

/// Microchip MCP2515 (CNF1-3): PRSEG and PHSEG1 3 bits each, PHSEG2 3 bits (min 2), BRP 6 bits.
pub const MCP2515: Limits = Limits {
    name: "mcp2515",
    tseg1: (3, 16),
    tseg2: (2, 8),
    sjw_max: 4,
    brp: (1, 64),
    brp_inc: 1,
};

/// ST bxCAN (CAN_BTR): TS1 4 bits, TS2 3 bits, SJW 2 bits, BRP 10 bits.
pub const BXCAN: Limits = Limits {
    name: "bxcan",
    tseg1: (1, 16),
    tseg2: (1, 8),
    sjw_max: 4,
    brp: (1, 1024),
    brp_inc: 1,
};

/// Bosch M_CAN 3.1+ nominal phase (NBTP): NTSEG1 8 bits, NTSEG2 7 bits, NSJW 7 bits, NBRP 9 bits.
pub const MCAN: Limits = Limits {
    name: "m_can",
    tseg1: (2, 256),
    tseg2: (2, 128),
    sjw_max: 128,
    brp: (1, 512),
    brp_inc: 1,
};

/// Bosch M_CAN 3.1+ data phase (DBTP): DTSEG1 5 bits, DTSEG2 4 bits, DSJW 4 bits, DBRP 5 bits.
pub const MCAN_DATA: Limits = Limits {
    name: "m_can-data",
    tseg1: (1, 32),
    tseg2: (1, 16),
    sjw_max: 16,
    brp: (1, 32),
    brp_inc: 1,
};

/// NXP FlexCAN classic (CTRL1): PROPSEG 3 bits + PSEG1 3 bits, PSEG2 3 bits (min 2), PRESDIV 8 bits.
pub const FLEXCAN: Limits = Limits {
    name: "flexcan",
    tseg1: (4, 16),
    tseg2: (2, 8),
    sjw_max: 4,
    brp: (1, 256),
    brp_inc: 1,
};

/// NXP FlexCAN with FD, nominal phase (CBT): EPROPSEG 6 + EPSEG1 5 bits, EPSEG2 5 bits, EPRESDIV 10.
pub const FLEXCAN_FD: Limits = Limits {
    name: "flexcan-fd",
    tseg1: (2, 96),
    tseg2: (2, 32),
    sjw_max: 16,
    brp: (1, 1024),
    brp_inc: 1,
};

/// NXP FlexCAN with FD, data phase (FDCBT): FPROPSEG 5 + FPSEG1 3 bits, FPSEG2 3 bits, FPRESDIV 10.
pub const FLEXCAN_FD_DATA: Limits = Limits {
    name: "flexcan-fd-data",
    tseg1: (2, 39),
    tseg2: (2, 8),
    sjw_max: 4,
    brp: (1, 1024),
    brp_inc: 1,
};

/// Every controller this module knows, by name.
pub const CONTROLLERS: [Limits; 8] = [
    SJA1000,
    MCP2515,
    BXCAN,
    MCAN,
    MCAN_DATA,
    FLEXCAN,
    FLEXCAN_FD,
    FLEXCAN_FD_DATA,
];

/// Look a controller up by name (case-insensitive; `mcan` and `m_can` both work).
pub fn controller(name: &str) -> Option<Limits> {
    fn normal(s: &str) -> impl Iterator<Item = u8> + '_ {
        s.bytes()
            .filter(|b| *b != b'_')
            .map(|b| b.to_ascii_lowercase())
    }
    CONTROLLERS
        .iter()
        .find(|c| normal(c.name).eq(normal(name)))
        .copied()
}

/// Computed timing, in the kernel's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BitTiming {
    /// The bitrate these registers give (may differ from the one asked for).
    pub bitrate: u32,
    /// Sample point in permille of the bit.
    pub sample_point_permille: u32,
    /// Time quantum in ns (truncated, as the kernel reports it).
    pub tq_ns: u32,
    /// Prescaler.
    pub brp: u32,
    /// Propagation segment in tq.
    pub prop_seg: u32,
    /// Phase segment 1 in tq.
    pub phase_seg1: u32,
    /// Phase segment 2 in tq.
    pub phase_seg2: u32,
    /// Synchronisation jump width in tq.
    pub sjw: u32,
    /// Bitrate error in parts per million of the requested bitrate (signed: actual − asked).
    pub bitrate_error_ppm: i64,
}

impl BitTiming {
    /// Time quanta per bit.
    pub fn tq_per_bit(&self) -> u32 {
        1 + self.prop_seg + self.phase_seg1 + self.phase_seg2
    }

    /// Sample point as a fraction of the bit.
    pub fn sample_point(&self) -> f64 {
        f64::from(self.sample_point_permille) / 1000.0
    }

    /// Bitrate error as a fraction of the requested bitrate.
    pub fn bitrate_error(&self) -> f64 {
        // |ppm| is at most a few thousand here: exact in f64.
        #[allow(clippy::cast_precision_loss)]
        let ppm = self.bitrate_error_ppm as f64;
        ppm / 1e6
    }
}

/// Why no timing fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BitTimingError {
    /// Zero bitrate or clock.
    #[error("bitrate and clock must be above zero")]
    Zero,
    /// The clock is too slow for the bitrate with the controller's smallest bit.
    #[error("a {clock} Hz clock cannot make {bitrate} bit/s on {controller}: even the shortest bit ({min_tq} tq at the smallest prescaler) is too long")]
    ClockTooSlow {
        /// Clock in Hz.
        clock: u32,
        /// Requested bitrate.
        bitrate: u32,
        /// Controller.
        controller: &'static str,
        /// Fewest tq per bit the controller allows.
        min_tq: u32,
    },
    /// No prescaler in range gives the bitrate.
    #[error("no prescaler within {min}..={max} gives {bitrate} bit/s from a {clock} Hz clock on {controller}")]
    NoPrescaler {
        /// Clock in Hz.
        clock: u32,
        /// Requested bitrate.
        bitrate: u32,
        /// Controller.
        controller: &'static str,
        /// Prescaler range.
        min: u32,
        /// Prescaler range.
        max: u32,
    },
    /// The closest bitrate is off by more than 5 %, the kernel's limit.
    #[error("the closest bitrate, {actual} bit/s, is {percent_whole}.{percent_tenths}% off {bitrate} bit/s (at most 5.0% is accepted)")]
    BitrateError {
        /// Requested bitrate.
        bitrate: u32,
        /// Closest achievable.
        actual: u32,
        /// Error in percent, integer part.
        percent_whole: u32,
        /// Error in percent, tenths.
        percent_tenths: u32,
    },
    /// A sample point outside (0, 1000) permille.
    #[error("sample point {0}‰ is outside 0‰..1000‰")]
    SamplePoint(u32),
}

/// The sample point CiA recommends for a bitrate, in permille (87.5 % up to 500 kbit/s, 80 % up
/// to 800 kbit/s, 75 % above).
pub const fn cia_sample_point(bitrate: u32) -> u32 {
    if bitrate > 800_000 {
        750
    } else if bitrate > 500_000 {
        800
    } else {
        875
    }
}

/// The kernel's choice of TSEG1/TSEG2 for `tseg` tq after sync: the larger of the two
/// candidates whose sample point does not pass the nominal one. Returns (sample point, error,
/// tseg1, tseg2).
fn split(limits: &Limits, nominal: u32, tseg: u32) -> (u32, u32, u32, u32) {
    let bit = tseg + 1;
    let mut best = (0, u32::MAX, 0, 0);
    for i in 0..=1u32 {
        let tseg2 = (bit - nominal * bit / 1000)
            .saturating_sub(i)
            .clamp(limits.tseg2.0, limits.tseg2.1);
        let mut tseg1 = tseg.saturating_sub(tseg2);
        let mut tseg2 = tseg2;
        if tseg1 > limits.tseg1.1 {
            tseg1 = limits.tseg1.1;
            tseg2 = tseg - tseg1;
        }
        let sample_point = 1000 * (bit - tseg2) / bit;
        let error = nominal.abs_diff(sample_point);
        if sample_point <= nominal && error < best.1 {
            best = (sample_point, error, tseg1, tseg2);
        }
    }
    best
}

/// Timing for `bitrate` from a `clock` Hz controller clock within `limits`, aiming at
/// `sample_point_permille` (CiA's recommendation when `None`). `sjw` defaults to 1 and is
/// limited to the controller's maximum and to PHASE_SEG2, as the kernel does.
pub fn calculate(
    clock: u32,
    bitrate: u32,
    sample_point_permille: Option<u32>,
    sjw: Option<u32>,
    limits: &Limits,
) -> Result<BitTiming, BitTimingError> {
    if clock == 0 || bitrate == 0 {
        return Err(BitTimingError::Zero);
    }
    let nominal = sample_point_permille.unwrap_or_else(|| cia_sample_point(bitrate));
    if nominal == 0 || nominal >= 1000 {
        return Err(BitTimingError::SamplePoint(nominal));
    }
    let min_tq = 1 + limits.tseg1.0 + limits.tseg2.0;
    if u64::from(clock) < u64::from(bitrate) * u64::from(min_tq) * u64::from(limits.brp.0) {
        return Err(BitTimingError::ClockTooSlow {
            clock,
            bitrate,
            controller: limits.name,
            min_tq,
        });
    }
    let brp_inc = limits.brp_inc.max(1);
    // (bitrate error, sample point error, tseg, brp)
    let mut best: Option<(u32, u32, u32, u32)> = None;
    let mut best_error = u32::MAX;
    let mut best_sp_error = u32::MAX;
    // tseg counts half quanta: even values round the prescaler down, odd ones up. The range is
    // bounded by the controller's limits.
    let top = (limits.tseg1.1 + limits.tseg2.1) * 2 + 1;
    let bottom = (limits.tseg1.0 + limits.tseg2.0) * 2;
    for tseg in (bottom..=top).rev() {
        let tsegall = 1 + tseg / 2;
        let brp = clock / (tsegall * bitrate) + tseg % 2;
        let brp = brp / brp_inc * brp_inc;
        if brp < limits.brp.0 || brp > limits.brp.1 {
            continue;
        }
        let actual = clock / (brp * tsegall);
        let error = bitrate.abs_diff(actual);
        if error > best_error {
            continue;
        }
        if error < best_error {
            best_sp_error = u32::MAX;
        }
        let (_, sp_error, _, _) = split(limits, nominal, tseg / 2);
        if sp_error >= best_sp_error {
            continue;
        }
        best_sp_error = sp_error;
        best_error = error;
        best = Some((error, sp_error, tseg / 2, brp));
        if error == 0 && sp_error == 0 {
            break;
        }
    }
    let Some((error, _, tseg, brp)) = best else {
        return Err(BitTimingError::NoPrescaler {
            clock,
            bitrate,
            controller: limits.name,
            min: limits.brp.0,
            max: limits.brp.1,
        });
    };
    let (sample_point, _, tseg1, tseg2) = split(limits, nominal, tseg);
    let actual = clock / (brp * (1 + tseg1 + tseg2));
    // Error in tenths of a percent, truncated, as the kernel judges it.
    let tenths = u32::try_from(u64::from(error) * 1000 / u64::from(bitrate)).unwrap_or(u32::MAX);
    if tenths > 50 {
        return Err(BitTimingError::BitrateError {
            bitrate,
            actual,
            percent_whole: tenths / 10,
            percent_tenths: tenths % 10,
        });
    }
    let prop_seg = tseg1 / 2;
    let sjw = sjw.unwrap_or(1).clamp(1, limits.sjw_max.max(1)).min(tseg2);
    Ok(BitTiming {
        bitrate: actual,
        sample_point_permille: sample_point,
        tq_ns: u32::try_from(u64::from(brp) * 1_000_000_000 / u64::from(clock)).unwrap_or(u32::MAX),
        brp,
        prop_seg,
        phase_seg1: tseg1 - prop_seg,
        phase_seg2: tseg2,
        sjw,
        bitrate_error_ppm: (i64::from(actual) - i64::from(bitrate)) * 1_000_000
            / i64::from(bitrate),
    })
}

/// Delays that a signal meets between two nodes, for the bus-length check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PropagationDelays {
    /// Cable delay per metre (about 5 ns/m for twisted pair).
    pub cable_ns_per_m: f64,
    /// One node's loop delay: transceiver transmit + receive plus controller input/output
    /// (ISO 11898-2 transceivers allow up to 255 ns loop delay; 250 ns is a safe default).
    pub node_loop_ns: f64,
}

impl Default for PropagationDelays {
    fn default() -> Self {
        PropagationDelays {
            cable_ns_per_m: 5.0,
            node_loop_ns: 250.0,
        }
    }
}

/// The longest bus (in metres) on which this timing still samples a bit after it has gone to the
/// far node and back: the round trip 2 × (cable + node loop) must fit in the time before the
/// sample point that the propagation segment can take, TSEG1 minus the SJW that PHASE_SEG1 must
/// keep for resynchronisation. `None` when even a zero-length bus does not fit.
pub fn max_bus_length_m(timing: &BitTiming, delays: &PropagationDelays) -> Option<f64> {
    let tq = 1e9 / f64::from(timing.bitrate.max(1)) / f64::from(timing.tq_per_bit());
    let usable_tq = (timing.prop_seg + timing.phase_seg1).saturating_sub(timing.sjw);
    let one_way_budget = f64::from(usable_tq) * tq / 2.0 - delays.node_loop_ns;
    (one_way_budget >= 0.0).then(|| one_way_budget / delays.cable_ns_per_m.max(f64::MIN_POSITIVE))
}

/// Bitrates a bus is commonly run at (CiA 301's table and the CAN FD data rates), fastest first.
pub const COMMON_BITRATES: [u32; 13] = [
    8_000_000, 5_000_000, 2_000_000, 1_000_000, 800_000, 500_000, 250_000, 125_000, 100_000,
    83_333, 50_000, 20_000, 10_000,
];

/// Timings for a bus of `length_m` that the asked-for one does not fit: at `bitrate`, the
/// earliest sample point (in steps of 0.5 %, up to 95 %) whose round trip fits; and the fastest
/// of [`COMMON_BITRATES`] at or below `bitrate` that fits with CiA's sample point. Each `None`
/// when there is none.
pub fn fitting_timings(
    clock: u32,
    bitrate: u32,
    sjw: Option<u32>,
    limits: &Limits,
    length_m: f64,
    delays: &PropagationDelays,
) -> (Option<BitTiming>, Option<BitTiming>) {
    let fits = |t: &BitTiming| max_bus_length_m(t, delays).is_some_and(|m| m >= length_m);
    let later = (cia_sample_point(bitrate)..=950)
        .step_by(5)
        .filter_map(|sp| calculate(clock, bitrate, Some(sp), sjw, limits).ok())
        .find(fits);
    let slower = COMMON_BITRATES
        .iter()
        .filter(|b| **b <= bitrate)
        .filter_map(|b| calculate(clock, *b, None, sjw, limits).ok())
        .find(fits);
    (later, slower)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classic_500k_on_sja1000_is_the_kernels_answer() {
        let t = calculate(8_000_000, 500_000, Some(875), Some(1), &SJA1000).unwrap();
        assert_eq!(
            (
                t.tq_ns,
                t.prop_seg,
                t.phase_seg1,
                t.phase_seg2,
                t.sjw,
                t.brp
            ),
            (125, 6, 7, 2, 1, 1)
        );
        assert_eq!(
            (t.bitrate, t.sample_point_permille, t.bitrate_error_ppm),
            (500_000, 875, 0)
        );
    }

    #[test]
    fn refuses_impossible_requests_saying_why() {
        let e = calculate(8_000_000, 5_000_000, None, None, &SJA1000).unwrap_err();
        assert!(
            matches!(e, BitTimingError::ClockTooSlow { min_tq: 3, .. }),
            "{e}"
        );
        let e = calculate(8_000_000, 950_000, None, None, &SJA1000).unwrap_err();
        assert!(matches!(e, BitTimingError::BitrateError { .. }), "{e}");
        assert_eq!(
            calculate(8_000_000, 500_000, Some(1000), None, &SJA1000),
            Err(BitTimingError::SamplePoint(1000))
        );
        assert_eq!(
            calculate(0, 1, None, None, &SJA1000),
            Err(BitTimingError::Zero)
        );
        let e = calculate(80_000_000, 100, None, None, &SJA1000).unwrap_err();
        assert!(matches!(e, BitTimingError::NoPrescaler { .. }), "{e}");
    }

    #[test]
    fn cia_defaults_and_lookup() {
        assert_eq!(cia_sample_point(500_000), 875);
        assert_eq!(cia_sample_point(800_000), 800);
        assert_eq!(cia_sample_point(1_000_000), 750);
        assert_eq!(controller("MCAN"), Some(MCAN));
        assert_eq!(controller("m_can-data"), Some(MCAN_DATA));
        assert_eq!(controller("nope"), None);
    }

    /// What the controllers' reference manuals allow, from their register field widths (a field
    /// of n bits holding value − 1 gives 1..=2^n): (TSEG1 range, TSEG2 range, SJW max, BRP range).
    /// Combined TSEG1 ranges add the PROP_SEG and PHASE_SEG1 fields where a controller has two.
    type Range = (u32, u32);
    const DATASHEETS: [(&str, Range, Range, u32, Range); 8] = [
        // SJA1000 BTR0/BTR1: TSEG1 4 bits, TSEG2 3 bits, SJW 2 bits, BRP 6 bits.
        ("sja1000", (1, 16), (1, 8), 4, (1, 64)),
        // MCP2515 CNF1-3: PRSEG 3 + PHSEG1 3 bits, PHSEG2 3 bits (at least 2 tq), SJW 2, BRP 6.
        ("mcp2515", (2, 16), (2, 8), 4, (1, 64)),
        // bxCAN CAN_BTR: TS1 4 bits, TS2 3 bits, SJW 2 bits, BRP 10 bits.
        ("bxcan", (1, 16), (1, 8), 4, (1, 1024)),
        // M_CAN NBTP: NTSEG1 8 bits (0 not allowed), NTSEG2 7 bits, NSJW 7 bits, NBRP 9 bits.
        ("m_can", (2, 256), (1, 128), 128, (1, 512)),
        // M_CAN DBTP: DTSEG1 5 bits, DTSEG2 4 bits, DSJW 4 bits, DBRP 5 bits.
        ("m_can-data", (1, 32), (1, 16), 16, (1, 32)),
        // FlexCAN CTRL1: PROPSEG 3 + PSEG1 3 bits, PSEG2 3 bits (at least 2 tq), RJW 2, PRESDIV 8.
        ("flexcan", (2, 16), (2, 8), 4, (1, 256)),
        // FlexCAN CBT: EPROPSEG 6 + EPSEG1 5 bits, EPSEG2 5 bits, ERJW 5 bits, EPRESDIV 10 bits.
        ("flexcan-fd", (2, 96), (1, 32), 32, (1, 1024)),
        // FlexCAN FDCBT: FPROPSEG 5 bits (from 0) + FPSEG1 3 bits, FPSEG2 3, FRJW 3, FPRESDIV 10.
        ("flexcan-fd-data", (1, 39), (1, 8), 8, (1, 1024)),
    ];

    #[test]
    fn controller_limits_lie_within_their_datasheets() {
        for (name, tseg1, tseg2, sjw, brp) in DATASHEETS {
            let c = controller(name).unwrap();
            let within =
                |ours: (u32, u32), sheet: (u32, u32)| sheet.0 <= ours.0 && ours.1 <= sheet.1;
            assert!(
                within(c.tseg1, tseg1),
                "{name} tseg1 {:?} vs {tseg1:?}",
                c.tseg1
            );
            assert!(
                within(c.tseg2, tseg2),
                "{name} tseg2 {:?} vs {tseg2:?}",
                c.tseg2
            );
            assert!(within(c.brp, brp), "{name} brp {:?} vs {brp:?}", c.brp);
            assert!(c.sjw_max <= sjw, "{name} sjw");
            // The largest register values are usable: no range is cut short at the top.
            assert_eq!(
                (c.tseg1.1, c.tseg2.1, c.brp.1),
                (tseg1.1, tseg2.1, brp.1),
                "{name}"
            );
        }
        assert_eq!(CONTROLLERS.len(), DATASHEETS.len());
    }

    #[test]
    fn a_bus_too_long_for_a_timing_gets_one_that_fits() {
        let delays = PropagationDelays::default();
        let (later, slower) = fitting_timings(40_000_000, 1_000_000, None, &MCAN, 40.0, &delays);
        for t in [later.unwrap(), slower.unwrap()] {
            assert!(max_bus_length_m(&t, &delays).unwrap() >= 40.0, "{t:?}");
        }
        assert_eq!(later.unwrap().bitrate, 1_000_000);
        assert!(
            later.unwrap().sample_point()
                > calculate(40_000_000, 1_000_000, None, None, &MCAN)
                    .unwrap()
                    .sample_point()
        );
        assert!(slower.unwrap().bitrate < 1_000_000);
        // Nothing fits a 10 km bus at 1 Mbit/s, but a slow enough rate does.
        let (later, slower) =
            fitting_timings(40_000_000, 1_000_000, None, &MCAN, 10_000.0, &delays);
        assert!(later.is_none());
        assert!(slower.is_none_or(|t| t.bitrate <= 10_000));
    }

    #[test]
    fn bus_length_follows_the_rule_of_thumb() {
        // 40 MHz M_CAN: 500 kbit/s allows about 100 m, 1 Mbit/s a few tens of metres.
        let d = PropagationDelays::default();
        let t = calculate(40_000_000, 500_000, None, Some(1), &MCAN).unwrap();
        let l = max_bus_length_m(&t, &d).unwrap();
        assert!((90.0..=130.0).contains(&l), "{l}");
        let t = calculate(40_000_000, 1_000_000, None, Some(1), &MCAN).unwrap();
        let l = max_bus_length_m(&t, &d).unwrap();
        assert!((15.0..=50.0).contains(&l), "{l}");
        // 8 MHz SJA1000 at 1 Mbit/s has 8 tq of 125 ns: no room left for cable.
        let t = calculate(8_000_000, 1_000_000, None, Some(1), &SJA1000).unwrap();
        assert!(max_bus_length_m(&t, &d).unwrap() < 1.0);
        let slow_nodes = PropagationDelays {
            node_loop_ns: 300.0,
            ..d
        };
        assert_eq!(max_bus_length_m(&t, &slow_nodes), None);
    }
}
