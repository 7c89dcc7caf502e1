use std::io::Write;

use anyhow::{anyhow, Context, Result};
use bywire_core::bittiming::{self, BitTiming, Limits, PropagationDelays};
use serde::Serialize;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  bywire bittiming --clock 8000000 --bitrate 500000 --controller sja1000\n  bywire bittiming --clock 40000000 --bitrate 500000 --sample-point 0.8 --dbitrate 2000000 --controller m_can --json\n\nControllers: sja1000, mcp2515, bxcan, m_can, flexcan, flexcan-fd (data phase: m_can-data, flexcan-fd-data).\nThe search is the Linux kernel's: the same registers `ip link set ... bitrate B sample-point P` sets."
)]
pub struct Args {
    /// Controller clock in Hz.
    #[arg(long)]
    clock: u32,
    /// Nominal bitrate in bit/s.
    #[arg(long)]
    bitrate: u32,
    /// Sample point as a fraction (0.875) or percent (87.5); default CiA's for the bitrate.
    #[arg(long)]
    sample_point: Option<f64>,
    /// Synchronisation jump width in tq (default 1, as the kernel).
    #[arg(long)]
    sjw: Option<u32>,
    /// Controller whose register limits apply.
    #[arg(long, default_value = "m_can")]
    controller: String,
    /// FD data-phase bitrate in bit/s.
    #[arg(long)]
    dbitrate: Option<u32>,
    /// FD data-phase sample point; default CiA's for the data bitrate.
    #[arg(long)]
    dsample_point: Option<f64>,
    /// Check that a bus of this many metres fits the timing's propagation budget.
    #[arg(long)]
    bus_length: Option<f64>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct TimingJson {
    controller: &'static str,
    bitrate: u32,
    sample_point: f64,
    tq_ns: u32,
    brp: u32,
    prop_seg: u32,
    phase_seg1: u32,
    phase_seg2: u32,
    sjw: u32,
    bitrate_error: f64,
    max_bus_length_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    data: Option<Box<TimingJson>>,
}

fn permille(fraction_or_percent: f64) -> Result<u32> {
    let fraction = if fraction_or_percent > 1.0 {
        fraction_or_percent / 100.0
    } else {
        fraction_or_percent
    };
    anyhow::ensure!(
        fraction > 0.0 && fraction < 1.0,
        "sample point {fraction_or_percent} is not between 0 and 1 (or 0 and 100 %)"
    );
    // Within (0, 1000): the cast cannot truncate meaningfully.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    Ok((fraction * 1000.0).round() as u32)
}

fn data_limits(nominal: &Limits) -> Result<Limits> {
    let name = match nominal.name {
        "m_can" | "m_can-data" => "m_can-data",
        "flexcan-fd" | "flexcan-fd-data" => "flexcan-fd-data",
        other => {
            return Err(anyhow!(
                "{other} has no CAN FD data phase; use m_can or flexcan-fd"
            ))
        }
    };
    bittiming::controller(name).ok_or_else(|| anyhow!("no data-phase limits for {name}"))
}

fn to_json(limits: &Limits, t: &BitTiming) -> TimingJson {
    TimingJson {
        controller: limits.name,
        bitrate: t.bitrate,
        sample_point: t.sample_point(),
        tq_ns: t.tq_ns,
        brp: t.brp,
        prop_seg: t.prop_seg,
        phase_seg1: t.phase_seg1,
        phase_seg2: t.phase_seg2,
        sjw: t.sjw,
        bitrate_error: t.bitrate_error(),
        max_bus_length_m: bittiming::max_bus_length_m(t, &PropagationDelays::default()),
        data: None,
    }
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let limits = bittiming::controller(&args.controller).ok_or_else(|| {
        anyhow!(
            "unknown controller '{}' (see --help for the list)",
            args.controller
        )
    })?;
    let sp = args.sample_point.map(permille).transpose()?;
    let nominal = bittiming::calculate(args.clock, args.bitrate, sp, args.sjw, &limits)
        .with_context(|| format!("no timing for {} bit/s", args.bitrate))?;
    let mut json = to_json(&limits, &nominal);
    if let Some(dbitrate) = args.dbitrate {
        let dlimits = data_limits(&limits)?;
        let dsp = args.dsample_point.map(permille).transpose()?;
        let data = bittiming::calculate(args.clock, dbitrate, dsp, args.sjw, &dlimits)
            .with_context(|| format!("no data-phase timing for {dbitrate} bit/s"))?;
        json.data = Some(Box::new(to_json(&dlimits, &data)));
    }
    if let (Some(length), max) = (args.bus_length, json.max_bus_length_m) {
        if !max.is_some_and(|m| length <= m) {
            let (later, slower) = bittiming::fitting_timings(
                args.clock,
                args.bitrate,
                args.sjw,
                &limits,
                length,
                &PropagationDelays::default(),
            );
            let mut fits = Vec::new();
            if let Some(t) = later {
                let percent = f64::from(t.sample_point_permille) / 10.0;
                fits.push(format!(
                    "at {} bit/s with the sample point at {percent} % (--sample-point {percent})",
                    t.bitrate
                ));
            }
            if let Some(t) = slower {
                fits.push(format!("at {} bit/s (--bitrate {})", t.bitrate, t.bitrate));
            }
            let suggestion = if fits.is_empty() {
                "no common bitrate fits it with this clock".to_string()
            } else {
                format!("it fits {}", fits.join(", or "))
            };
            anyhow::bail!(
                "a {length} m bus does not fit this timing: the round trip must end before the sample point (longest: {}); {suggestion}",
                max.map_or("none".to_string(), |m| format!("{m:.1} m"))
            );
        }
    }
    if args.json {
        serde_json::to_writer(&mut *out, &json)?;
        writeln!(out)?;
        return Ok(());
    }
    print_human(&json, "nominal", out)?;
    if let Some(data) = &json.data {
        print_human(data, "data", out)?;
    }
    Ok(())
}

fn print_human(t: &TimingJson, phase: &str, out: &mut impl Write) -> Result<()> {
    writeln!(out, "{phase} phase ({}):", t.controller)?;
    writeln!(
        out,
        "  bitrate {} bit/s (error {:+.3} %), sample point {:.1} %",
        t.bitrate,
        t.bitrate_error * 100.0,
        t.sample_point * 100.0
    )?;
    writeln!(
        out,
        "  tq {} ns  brp {}  prop-seg {}  phase-seg1 {}  phase-seg2 {}  sjw {}  ({} tq per bit)",
        t.tq_ns,
        t.brp,
        t.prop_seg,
        t.phase_seg1,
        t.phase_seg2,
        t.sjw,
        1 + t.prop_seg + t.phase_seg1 + t.phase_seg2
    )?;
    match t.max_bus_length_m {
        Some(m) => writeln!(
            out,
            "  longest bus about {m:.0} m (5 ns/m cable, 250 ns node loop delay)"
        )?,
        None => writeln!(
            out,
            "  too little time before the sample point for any bus length"
        )?,
    }
    Ok(())
}
