//! `bywire dataset`: logs → a training dataset (`bywire_data::dataset` on a grid, written by
//! `bywire_data::table`), with its card (JSON and Markdown) and, for simulator runs,
//! the ground truth (`truth.csv`) joined on the grid.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, ensure, Context, Result};
use bywire_data::dataset::{Builder, Column, Config, Role, Row, Summary};
use bywire_data::latency::SignalRef;
use bywire_data::table::{TableColumn, TableWriter};
use bywire_data::truth::Truth;
use bywire_dbc::decoder::Decoder;
use serde_json::json;

use crate::support::logs;
use crate::support::vehicles;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire dataset drive1.log drive2.blf --profile reference-tug --rate 50 --out ds
  bywire dataset run/bus1.log --profile reference-tug --truth run/truth.csv --out ds
  bywire dataset bus1.log bus3.log --profile reference-tug --signal bms_state=Battery.BmsState --out ds
  bywire sim --sweep apron-loop --seeds 1..8 --out sweep && bywire dataset --runs sweep --profile reference-tug --out ds

Writes into --out (a new or empty folder): dataset.parquet (one row per grid step: t_s,
timestamp_s, run, episode, split, then each action and observation by the profile's roles
(command, state, wheel speeds and angles, IMU, battery), the 4WS odometry's pose from each
episode's start (odom_x, odom_y, odom_yaw, odom_vx, odom_vy, odom_yaw_rate; with the profile's
geometry), each observation's age_s — the time since a frame last carried it; the pose's is its
oldest input's —, and truth_* columns with --truth; units in the fields' metadata) and card.json / card.md (columns, units, rate, episodes, statistics, the
source files' SHA-256, the profile and DBC). Episodes end at a change of control mode, steering
mode or E-stop state and at a command gap (5 command periods); the split is by episode.")]
pub struct Args {
    /// Logs (any format; several are merged in time order).
    #[arg(required_unless_present = "runs", conflicts_with = "runs")]
    logs: Vec<PathBuf>,
    /// A sweep's folder (`bywire sim --sweep`): every run in it (a folder with metrics.json),
    /// its bus1.log and bus3.log with its truth.csv, into one table with a `run` column.
    #[arg(long, value_name = "DIR", conflicts_with = "truth")]
    runs: Option<PathBuf>,
    /// The vehicle profile (built in, e.g. reference-tug, or a TOML file).
    #[arg(long)]
    profile: String,
    /// Grid rate, Hz.
    #[arg(long, default_value = "50", value_parser = crate::support::numbers::rate)]
    rate: f64,
    /// More observations: NAME=MESSAGE.SIGNAL. Repeatable.
    #[arg(long, value_name = "NAME=MSG.SIGNAL")]
    signal: Vec<String>,
    /// A simulator run's truth.csv, joined on the grid as truth_* columns.
    #[arg(long, value_name = "FILE")]
    truth: Option<PathBuf>,
    /// Share of episodes for validation.
    #[arg(long, default_value_t = 0.2)]
    validation: f64,
    /// Seed of the split.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The folder to write.
    #[arg(long)]
    out: PathBuf,
}

/// One run's inputs: its logs, its truth, its name in the `run` column.
struct Source {
    logs: Vec<PathBuf>,
    truth: Option<PathBuf>,
    name: Option<String>,
}

/// The runs of a sweep's folder, in name order.
fn sweep_sources(dir: &Path) -> Result<Vec<Source>> {
    let mut folders: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("--runs {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("metrics.json").is_file())
        .collect();
    folders.sort();
    ensure!(
        !folders.is_empty(),
        "--runs {}: no run folders (with metrics.json) in it",
        dir.display()
    );
    Ok(folders
        .into_iter()
        .map(|f| Source {
            logs: ["bus1.log", "bus3.log"]
                .iter()
                .map(|n| f.join(n))
                .filter(|p| p.is_file())
                .collect(),
            truth: Some(f.join("truth.csv")).filter(|p| p.is_file()),
            name: f.file_name().map(|n| n.to_string_lossy().into_owned()),
        })
        .collect())
}

/// Column statistics: values, sum, min, max.
type Stats = Vec<(u64, f64, f64, f64)>;

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    ensure!(
        (0.0..=1.0).contains(&args.validation),
        "--validation {}: a share from 0 to 1",
        args.validation
    );
    let sources = match &args.runs {
        Some(dir) => sweep_sources(dir)?,
        None => vec![Source {
            logs: args.logs.clone(),
            truth: args.truth.clone(),
            name: None,
        }],
    };
    let loaded = vehicles::load_profile(&args.profile)?;
    let mut config = Config::from_profile(&loaded, args.rate);
    config.validation = args.validation;
    config.seed = args.seed;
    for text in &args.signal {
        let (name, source) = text
            .split_once('=')
            .and_then(|(n, s)| Some((n, SignalRef::parse(s)?)))
            .filter(|(n, _)| !n.is_empty())
            .ok_or_else(|| anyhow!("--signal '{text}': expected NAME=MESSAGE.SIGNAL"))?;
        config.columns.push(Column {
            name: name.to_string(),
            role: Role::Observation,
            source,
            unit: String::new(),
            cuts_episodes: false,
        });
    }
    let decoder = Decoder::new(loaded.database);
    // The columns (with the DBC's units) and the truth's, from the first run's truth.csv.
    let columns = Builder::new(&decoder, config.clone())?.columns().to_vec();
    // The first run's truth header names the truth columns (each run's rows are read in turn).
    let truth_columns = match sources.iter().find_map(|s| s.truth.as_deref()) {
        Some(path) => Truth::columns_of(path)?,
        None => Vec::new(),
    };
    let mut table_columns: Vec<TableColumn> = columns
        .iter()
        .map(|c| TableColumn {
            name: c.name.clone(),
            unit: c.unit.clone(),
        })
        .collect();
    for c in columns.iter().filter(|c| c.role.has_age()) {
        table_columns.push(TableColumn {
            name: format!("{}_age_s", c.name),
            unit: "s".into(),
        });
    }
    for name in &truth_columns {
        table_columns.push(TableColumn {
            name: name.clone(),
            unit: Truth::unit(name).into(),
        });
    }
    let folder = &args.out;
    if folder.exists() {
        ensure!(
            std::fs::read_dir(folder)?.next().is_none(),
            "--out {}: not empty (a dataset is written into a new or empty folder)",
            folder.display()
        );
    }
    std::fs::create_dir_all(folder).with_context(|| format!("--out {}", folder.display()))?;
    let mut table = TableWriter::create(&folder.join("dataset.parquet"), &table_columns)?;
    let mut stats: Stats = vec![(0, 0.0, f64::INFINITY, f64::NEG_INFINITY); table_columns.len()];
    let mut total = Summary::default();
    for source in &sources {
        let truth = source.truth.as_deref().map(Truth::read).transpose()?;
        if let Some(t) = &truth {
            ensure!(
                t.columns() == truth_columns,
                "{}: its columns differ from the first run's truth",
                source.truth.as_deref().unwrap_or(Path::new("")).display()
            );
        }
        let mut builder = Builder::new(&decoder, config.clone())?;
        builder.offset_episodes(u32::try_from(total.episodes.len()).unwrap_or(u32::MAX));
        let summary = build(
            source,
            builder,
            truth,
            truth_columns.len(),
            &columns,
            &mut table,
            &mut stats,
        )?;
        total.records += summary.records;
        total.rows += summary.rows;
        total.rows_outside += summary.rows_outside;
        total.rows_skipped += summary.rows_skipped;
        total.episodes.extend(summary.episodes);
    }
    let rows = table.finish()?;
    let card = card(
        args,
        &sources,
        &loaded.profile.name,
        &table_columns,
        &stats,
        &total,
    )?;
    std::fs::write(
        folder.join("card.json"),
        serde_json::to_string_pretty(&card)? + "\n",
    )?;
    std::fs::write(folder.join("card.md"), card_markdown(&card))?;
    writeln!(
        out,
        "{rows} rows at {} Hz from {} run(s), {} episodes ({} for validation), {} rows outside episodes; {}",
        args.rate,
        sources.len(),
        total.episodes.len(),
        total.episodes.iter().filter(|e| e.validation).count(),
        total.rows_outside,
        folder.join("dataset.parquet").display()
    )?;
    Ok(())
}

/// One source's rows into `table`.
fn build(
    source: &Source,
    mut builder: Builder<'_>,
    mut truth: Option<Truth>,
    truth_width: usize,
    columns: &[Column],
    table: &mut TableWriter,
    stats: &mut Stats,
) -> Result<Summary> {
    let observations: Vec<usize> = (0..columns.len())
        .filter(|&i| columns.get(i).is_some_and(|c| c.role.has_age()))
        .collect();
    let mut first_timestamp: Option<f64> = None;
    let mut failure: Option<std::io::Error> = None;
    let run = source.name.as_deref();
    let mut write_row = |row: Row, first: f64| {
        if failure.is_some() {
            return;
        }
        let timestamp = first + row.t_s;
        let mut values = row.values;
        values.extend(
            observations
                .iter()
                .map(|&i| row.ages.get(i).copied().unwrap_or(f64::NAN)),
        );
        match truth.as_mut() {
            Some(truth) => values.extend(truth.at(timestamp)),
            None => values.extend(std::iter::repeat_n(f64::NAN, truth_width)),
        }
        for (s, v) in stats.iter_mut().zip(&values) {
            if !v.is_nan() {
                *s = (s.0 + 1, s.1 + v, s.2.min(*v), s.3.max(*v));
            }
        }
        let split = row.episode.map(|_| {
            if row.validation {
                "validation"
            } else {
                "train"
            }
        });
        if let Err(e) = table.push(row.t_s, timestamp, run, row.episode, split, &values) {
            failure = Some(e);
        }
    };
    logs::for_each_merged(&source.logs, |record| {
        let first = *first_timestamp.get_or_insert(record.timestamp.as_nanos() as f64 / 1e9);
        builder.push(record.timestamp, &record.frame, &mut |row| {
            write_row(row, first)
        });
    })?;
    let first = first_timestamp.unwrap_or(0.0);
    let summary = builder.finish(&mut |row| write_row(row, first));
    if let Some(e) = failure {
        return Err(e).context("writing dataset.parquet");
    }
    Ok(summary)
}

fn card(
    args: &Args,
    sources: &[Source],
    profile: &str,
    columns: &[TableColumn],
    stats: &[(u64, f64, f64, f64)],
    summary: &Summary,
) -> Result<serde_json::Value> {
    let sources = sources
        .iter()
        .flat_map(|s| s.logs.iter().chain(s.truth.iter()))
        .map(|p| Ok(json!({"file": p.display().to_string(), "sha256": crate::support::files::sha256(p)?})))
        .collect::<Result<Vec<_>>>()?;
    Ok(json!({
        "rate_hz": args.rate,
        "rows": summary.rows,
        "records_read": summary.records,
        "rows_outside_episodes": summary.rows_outside,
        "grid_points_skipped_in_silences": summary.rows_skipped,
        "profile": profile,
        "validation_share": args.validation,
        "split_seed": args.seed,
        "sources": sources,
        "columns": columns.iter().zip(stats).map(|(c, (n, sum, min, max))| json!({
            "name": c.name,
            "unit": c.unit,
            "values": n,
            "mean": if *n > 0 { Some(sum / *n as f64) } else { None },
            "min": if *n > 0 { Some(*min) } else { None },
            "max": if *n > 0 { Some(*max) } else { None },
        })).collect::<Vec<_>>(),
        "episodes": summary.episodes.iter().map(|e| json!({
            "episode": e.index,
            "start_s": e.start_s,
            "end_s": e.end_s,
            "rows": e.rows,
            "split": if e.validation { "validation" } else { "train" },
        })).collect::<Vec<_>>(),
    }))
}

fn card_markdown(card: &serde_json::Value) -> String {
    let mut md = String::from("# Dataset card\n\n");
    md.push_str(&format!(
        "- rate: {} Hz; rows: {}; profile: {}\n- validation share {} (seed {}), by episode\n\n## Sources\n\n",
        card["rate_hz"], card["rows"], card["profile"], card["validation_share"], card["split_seed"]
    ));
    for s in card["sources"].as_array().into_iter().flatten() {
        md.push_str(&format!(
            "- `{}` sha256 `{}`\n",
            s["file"].as_str().unwrap_or(""),
            s["sha256"].as_str().unwrap_or("")
        ));
    }
    md.push_str("\n## Columns\n\n| column | unit | values | mean | min | max |\n|---|---|---|---|---|---|\n");
    for c in card["columns"].as_array().into_iter().flatten() {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            c["name"].as_str().unwrap_or(""),
            c["unit"].as_str().unwrap_or(""),
            c["values"],
            c["mean"],
            c["min"],
            c["max"]
        ));
    }
    md.push_str(
        "\n## Episodes\n\n| episode | start s | end s | rows | split |\n|---|---|---|---|---|\n",
    );
    for e in card["episodes"].as_array().into_iter().flatten() {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            e["episode"],
            e["start_s"],
            e["end_s"],
            e["rows"],
            e["split"].as_str().unwrap_or("")
        ));
    }
    md
}
