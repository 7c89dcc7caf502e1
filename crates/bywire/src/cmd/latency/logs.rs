//! `bywire latency LOG...`: the figures of `bywire_data::latency`, as text or JSON.

use std::io::Write;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use bywire_data::latency::{Analyzer, Config, Distribution, Report, SignalRef};
use bywire_dbc::decoder::Decoder;
use serde_json::{json, Value};

use super::Args;
use crate::support::logs;
use crate::support::{dbc, vehicles};

fn pair(text: &str, option: &str) -> Result<(SignalRef, SignalRef)> {
    let parsed = text
        .split_once('=')
        .and_then(|(a, b)| Some((SignalRef::parse(a)?, SignalRef::parse(b)?)));
    parsed.ok_or_else(|| anyhow!("{option} '{text}': expected MESSAGE.SIGNAL=MESSAGE.SIGNAL"))
}

fn config(args: &Args) -> Result<(Decoder, Config)> {
    let (database, mut config) = match (&args.profile, &args.dbc) {
        (Some(name), _) => {
            let loaded = vehicles::load_profile(name)?;
            let config = Config::from_profile(&loaded);
            (loaded.database, config)
        }
        (None, Some(path)) => (dbc::load(path, false)?, Config::default()),
        (None, None) => bail!("give --profile or --dbc (or --predict DBC --bitrate B)"),
    };
    if let Some(echo) = &args.echo {
        config.echo = Some(pair(echo, "--echo")?);
    }
    if !args.response.is_empty() {
        config.responses = args
            .response
            .iter()
            .map(|r| pair(r, "--response"))
            .collect::<Result<_>>()?;
    }
    anyhow::ensure!(
        args.step_min.is_finite() && args.step_min > 0.0,
        "--step-min must be above 0"
    );
    config.step_min = args.step_min;
    config.window = Duration::from_secs_f64(args.window / 1e3);
    config.step_window = Duration::from_secs_f64(args.step_window);
    for text in &args.transfer {
        let (from, to) = text
            .split_once('=')
            .filter(|(a, b)| !a.is_empty() && !b.is_empty() && a != b)
            .ok_or_else(|| anyhow!("--transfer '{text}': expected FROM=TO, two channels"))?;
        config.transfers.push((from.to_string(), to.to_string()));
    }
    Ok((Decoder::new(database), config))
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    if let Some(plot) = &args.plot {
        let extension = plot
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        anyhow::ensure!(
            matches!(extension.as_deref(), Some("png" | "svg")),
            "--plot {}: the image must end in .png or .svg",
            plot.display()
        );
    }
    let (decoder, config) = config(args)?;
    let mut analyzer = Analyzer::new(&decoder, config)?;
    logs::for_each_merged(&args.logs, |record| {
        analyzer.push(record.timestamp, &record.interface, &record.frame);
    })?;
    let report = analyzer.finish();
    if let Some(plot) = &args.plot {
        crate::plot::latency::write(&report, plot)?;
    }
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &to_json(&report)).context("writing JSON")?;
        writeln!(out)?;
    } else {
        print_text(&report, out)?;
    }
    Ok(())
}

fn distribution(d: &Distribution) -> Value {
    json!({
        "count": d.count,
        "min_ms": d.min_ms,
        "mean_ms": d.mean_ms,
        "p50_ms": d.p50_ms,
        "p90_ms": d.p90_ms,
        "p99_ms": d.p99_ms,
        "max_ms": d.max_ms,
        "histogram": d.histogram.iter().map(|(edge, n)| json!([edge, n])).collect::<Vec<_>>(),
    })
}

fn to_json(report: &Report) -> Value {
    json!({
        "records": report.records,
        "echo": report.echo.as_ref().map(distribution),
        "echo_missing": report.echo_missing,
        "responses": report.responses.iter().map(|r| json!({
            "setpoint": r.setpoint.to_string(),
            "actual": r.actual.to_string(),
            "steps": r.steps.iter().map(|s| json!({
                "at_s": s.at_s,
                "from": s.from,
                "to": s.to,
                "dead_time_s": s.t10_s,
                "t50_s": s.t50_s,
                "t90_s": s.t90_s,
                "rise_s": s.metrics.and_then(|m| m.rise_time),
                "settling_2_s": s.metrics.map(|m| m.settling_time_2),
                "settling_5_s": s.metrics.map(|m| m.settling_time_5),
                "overshoot_percent": s.metrics.map(|m| m.overshoot_percent),
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "cycles": report.cycles.iter().map(|c| json!({
            "channel": c.channel,
            "message": c.message,
            "id": format!("0x{:X}", c.raw_id & 0x1FFF_FFFF),
            "nominal_ms": c.nominal_ms,
            "frames": c.frames,
            "mean_ms": c.mean_ms,
            "min_ms": c.min_ms,
            "max_ms": c.max_ms,
            "jitter_ms": c.jitter_ms,
            "late_gaps": c.late_gaps,
        })).collect::<Vec<_>>(),
        "transfers": report.transfers.iter().map(|t| json!({
            "from": t.from,
            "to": t.to,
            "latency": t.latency.as_ref().map(distribution),
            "unmatched": t.unmatched,
        })).collect::<Vec<_>>(),
    })
}

fn line(d: &Distribution) -> String {
    format!(
        "{} samples, min {:.3} ms, p50 {:.2}, p90 {:.2}, p99 {:.2}, max {:.3} ms, mean {:.3} ms",
        d.count, d.min_ms, d.p50_ms, d.p90_ms, d.p99_ms, d.max_ms, d.mean_ms
    )
}

fn seconds(s: Option<f64>) -> String {
    s.map_or_else(|| "-".into(), |s| format!("{:.3}", s))
}

fn print_text(report: &Report, out: &mut impl Write) -> Result<()> {
    writeln!(out, "{} records", report.records)?;
    if let Some(echo) = &report.echo {
        writeln!(out, "command → echo: {}", line(echo))?;
        writeln!(out, "  commands never echoed: {}", report.echo_missing)?;
    }
    for t in &report.transfers {
        match &t.latency {
            Some(d) => writeln!(out, "transfer {} → {}: {}", t.from, t.to, line(d))?,
            None => writeln!(out, "transfer {} → {}: no frame arrived", t.from, t.to)?,
        }
        writeln!(out, "  unmatched: {}", t.unmatched)?;
    }
    for r in &report.responses {
        writeln!(
            out,
            "{} → {}: {} steps",
            r.setpoint,
            r.actual,
            r.steps.len()
        )?;
        if !r.steps.is_empty() {
            writeln!(
                out,
                "  {:>9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>10} {:>9}",
                "at s",
                "from",
                "to",
                "dead s",
                "t50 s",
                "t90 s",
                "rise s",
                "settle5 s",
                "overshoot"
            )?;
        }
        for s in &r.steps {
            let m = s.metrics;
            writeln!(
                out,
                "  {:>9.3} {:>9.3} {:>9.3} {:>9} {:>8} {:>8} {:>8} {:>10} {:>8}",
                s.at_s,
                s.from,
                s.to,
                seconds(s.t10_s),
                seconds(s.t50_s),
                seconds(s.t90_s),
                seconds(m.and_then(|m| m.rise_time)),
                seconds(m.map(|m| m.settling_time_5)),
                m.map_or_else(|| "-".into(), |m| format!("{:.1} %", m.overshoot_percent)),
            )?;
        }
    }
    writeln!(out, "cycle times:")?;
    writeln!(
        out,
        "  {:<8} {:<28} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>5}",
        "channel", "message", "nominal", "frames", "mean ms", "min ms", "max ms", "jitter", "late"
    )?;
    for c in &report.cycles {
        writeln!(
            out,
            "  {:<8} {:<28} {:>9} {:>8} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>5}",
            c.channel,
            c.message,
            c.nominal_ms
                .map_or_else(|| "-".into(), |n| format!("{n:.1}")),
            c.frames,
            c.mean_ms,
            c.min_ms,
            c.max_ms,
            c.jitter_ms,
            c.late_gaps
        )?;
    }
    Ok(())
}
