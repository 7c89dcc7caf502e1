//! Many runs at once: scenarios × seeds × payloads × grades, as fast as possible on a fixed
//! number of threads, each run into its own folder ([`crate::output::write_run`]), with one
//! summary row per run. Runs are deterministic, so a sweep's folders are the same whatever
//! the number of threads.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use bywire_core::Timestamp;

use crate::report::RunReport;
use crate::scenario::Scenario;
use crate::tug::Tug;

/// One run of a sweep.
#[derive(Debug, Clone)]
pub struct Job {
    /// What it drives.
    pub scenario: Scenario,
    /// Its seed.
    pub seed: u64,
    /// Payload, kg.
    pub payload: f64,
    /// Grade (rise over run).
    pub grade: f64,
}

impl Job {
    /// Its folder's name: `SCENARIO_seedS_payloadP_gradeG`.
    pub fn folder(&self) -> String {
        let name: String = self
            .scenario
            .name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        format!(
            "{name}_seed{}_payload{}_grade{}",
            self.seed, self.payload, self.grade
        )
    }
}

/// Every combination, in a fixed order (scenario, then seed, payload, grade).
pub fn jobs(
    scenarios: &[Scenario],
    seeds: std::ops::RangeInclusive<u64>,
    payloads: &[f64],
    grades: &[f64],
) -> Vec<Job> {
    let mut jobs = Vec::new();
    for scenario in scenarios {
        let payloads = if payloads.is_empty() {
            vec![scenario.tug.payload]
        } else {
            payloads.to_vec()
        };
        let grades = if grades.is_empty() {
            vec![scenario.tug.grade]
        } else {
            grades.to_vec()
        };
        for seed in seeds.clone() {
            for &payload in &payloads {
                for &grade in &grades {
                    jobs.push(Job {
                        scenario: scenario.clone(),
                        seed,
                        payload,
                        grade,
                    });
                }
            }
        }
    }
    jobs
}

/// What one run gave: its folder and report, or why it failed.
pub type Outcome = Result<(PathBuf, RunReport), String>;

/// Run `jobs` on `threads` threads, each for at most `limit` simulated time (logs timed from
/// `start`, since the Unix epoch), into folders under `out`; `done(index, outcome)` is told of
/// each as it ends (from the worker threads, one at a time). The outcomes in the jobs' order.
pub fn run(
    jobs: &[Job],
    threads: usize,
    limit: Timestamp,
    start: Timestamp,
    out: &Path,
    done: &(dyn Fn(usize, &Outcome) + Sync),
) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let outcomes: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; jobs.len()]);
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            scope.spawn(|| loop {
                let index = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(index) else { break };
                let outcome = run_one(job, limit, start, out);
                // Told and stored under the lock: reports come one at a time.
                if let Ok(mut outcomes) = outcomes.lock() {
                    done(index, &outcome);
                    if let Some(slot) = outcomes.get_mut(index) {
                        *slot = Some(outcome);
                    }
                }
            });
        }
    });
    outcomes
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .map(|o| o.unwrap_or_else(|| Err("not run".into())))
        .collect()
}

fn run_one(job: &Job, limit: Timestamp, start: Timestamp, out: &Path) -> Outcome {
    let mut params = job.scenario.params(job.seed, job.payload);
    params.grade = job.grade;
    let mut tug = Tug::new(params).map_err(|e| e.to_string())?;
    let wall = Instant::now();
    let completed = job.scenario.run_fast(&mut tug, limit);
    let report = RunReport::of(
        &tug,
        &job.scenario.name,
        job.seed,
        start,
        completed,
        wall.elapsed(),
    );
    let dir = out.join(job.folder());
    crate::output::write_run(&tug, &report, &dir).map_err(|e| e.to_string())?;
    Ok((dir, report))
}

/// The summary's columns.
pub const SUMMARY_COLUMNS: &str = "folder,scenario,seed,payload_kg,grade,completed,sim_seconds,wall_seconds,tracking_max_m,tracking_mean_m,echo_p50_ms,echo_max_ms,battery_soc,error";

/// One summary row (CSV) for a job and its outcome.
pub fn summary_row(job: &Job, outcome: &Outcome) -> String {
    let head = format!(
        "{},{},{},{},{}",
        job.folder(),
        job.scenario.name.replace(',', "_"),
        job.seed,
        job.payload,
        job.grade
    );
    let number = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    match outcome {
        Ok((_, r)) => format!(
            "{head},{},{},{},{},{},{},{},{},",
            r.completed,
            r.sim_seconds,
            r.wall_seconds,
            r.tracking_error_m.max,
            r.tracking_error_m.mean,
            number(r.echo_latency_ms.p50),
            number(r.echo_latency_ms.max),
            r.battery_soc
        ),
        Err(e) => format!("{head},,,,,,,,,{}", e.replace([',', '\n'], " ")),
    }
}
