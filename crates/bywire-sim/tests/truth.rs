//! The ground truth a run writes (`truth.csv`) is the plant's own state: every 10 ms, equal to
//! the run's trace where both have a sample, and read back to the same numbers.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use bywire_core::Timestamp;
use bywire_sim::truth::{write_csv, COLUMNS};
use bywire_sim::tug::{Tug, TugParams};

#[test]
fn truth_is_the_plants_state_every_10_ms() {
    let mut tug = Tug::new(TugParams::default()).unwrap();
    while tug.now().as_nanos() < 8_000_000_000 {
        tug.step();
    }
    assert_eq!(tug.truth.len(), 800);
    for (i, s) in tug.truth.iter().enumerate() {
        assert_eq!(s.t.as_nanos(), (i as u64 + 1) * 10_000_000);
    }
    // Where the 50 ms trace has a sample, the truth's pose and front-left angle are its own.
    let mut matched = 0;
    for sample in &tug.trace {
        let truth = tug.truth.iter().find(|t| t.t == sample.t).unwrap();
        assert_eq!(truth.pose, sample.pose);
        assert_eq!(truth.wheel_angles_deg[0], sample.steering_actual);
        matched += 1;
    }
    assert!(matched >= 150, "{matched}");
    // The tug drove: it moved, and its wheels turned.
    let last = tug.truth.last().unwrap();
    assert!(last.pose.x.hypot(last.pose.y) > 1.0, "{:?}", last.pose);
    assert!(tug.truth.iter().any(|t| t.wheel_speeds[0] > 0.5));

    // On the logs' clock: from a start time given (2026-12-07T08:00:00Z), to the microsecond.
    let start = Timestamp::from_nanos(1_796_630_400_000_000_000);
    let mut csv = Vec::new();
    write_csv(&tug.truth, start, &mut csv).unwrap();
    let text = String::from_utf8(csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), COLUMNS.join(","));
    for (line, s) in lines.zip(&tug.truth) {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), COLUMNS.len());
        let number = |i: usize| cells[i].parse::<f64>().unwrap();
        let t = 1_796_630_400_000_000_000 + s.t.as_nanos();
        assert_eq!(
            cells[0],
            format!("{}.{:06}", t / 1_000_000_000, t % 1_000_000_000 / 1_000)
        );
        assert_eq!(
            (number(1), number(2), number(3)),
            (s.pose.x, s.pose.y, s.pose.yaw)
        );
        assert_eq!(number(6), s.twist.omega);
        for k in 0..4 {
            assert_eq!(number(7 + k), s.wheel_angles_deg[k]);
            assert_eq!(number(11 + k), s.wheel_speeds[k]);
        }
        let mode = s.steering_mode.map(|m| m.to_string()).unwrap_or_default();
        assert_eq!(cells[15], mode);
    }
}
