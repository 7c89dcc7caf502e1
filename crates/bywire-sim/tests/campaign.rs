//! The default campaign (`campaigns/default.toml`): every cell executed passes or does not
//! apply with its reason, the same whatever the number of threads; and with each mechanism the
//! vehicle's software has switched off, cells fail and the report says so.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::collections::BTreeSet;
use std::path::Path;

use bywire_sim::campaign::{self, report, Campaign, CellResult, FaultClass, Verdict};
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

fn default_campaign() -> Campaign {
    Campaign::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../campaigns/default.toml"))
        .unwrap()
}

fn run(c: &Campaign, jobs: usize, disabled: Mechanisms) -> Vec<CellResult> {
    campaign::run(c, jobs, disabled, &|_| {}).unwrap()
}

/// Verifies: REQ-FI-1, REQ-CAN-1
#[test]
fn the_default_campaign_passes_every_cell_it_can_run_on_three_vehicles() {
    let c = default_campaign();
    let results = run(&c, 2, Mechanisms::NONE);
    let failed: Vec<String> = results
        .iter()
        .filter(|r| r.verdict == Verdict::Fail)
        .map(|r| format!("{}: {}", r.name, r.why))
        .collect();
    assert!(failed.is_empty(), "{failed:#?}");
    // Every fault class, on three vehicles (two of them not the plain tug), in five states.
    let classes: BTreeSet<FaultClass> = c.faults.iter().map(|f| f.class).collect();
    assert_eq!(classes.len(), FaultClass::ALL.len());
    assert!(classes.len() >= 20);
    let profiles: BTreeSet<&str> = results.iter().map(|r| r.profile.as_str()).collect();
    assert_eq!(profiles.len(), 3);
    assert_eq!(results.len(), 3 * 5 * c.faults.len());
    // A cell that does not apply says why; one that passes was watched.
    for r in &results {
        match r.verdict {
            Verdict::NotApplicable => assert!(!r.why.is_empty(), "{}", r.name),
            _ => assert!(r.why.is_empty(), "{}", r.name),
        }
    }
    // Every mechanism the vehicle's supervisor has is expected by some executed cell.
    let expected: BTreeSet<Mechanism> = results
        .iter()
        .filter(|r| r.verdict == Verdict::Pass)
        .filter_map(|r| r.expected.mechanism)
        .collect();
    for m in [
        Mechanism::Can,
        Mechanism::E2e,
        Mechanism::Timeout,
        Mechanism::Range,
        Mechanism::Redundancy,
        Mechanism::SafeState,
        Mechanism::Secoc,
        Mechanism::Takeover,
    ] {
        assert!(expected.contains(&m), "no cell expects {m}");
    }
    // Deterministic: one thread gives the same cells.
    let again = run(&c, 1, Mechanisms::NONE);
    let strip = |rs: &[CellResult]| {
        rs.iter()
            .map(|r| CellResult {
                wall_seconds: 0.0,
                ..r.clone()
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(strip(&results), strip(&again));
}

/// Verifies: REQ-FI-1
#[test]
fn each_mechanism_switched_off_fails_cells_and_the_report_names_them() {
    let c = default_campaign();
    let dir = std::env::temp_dir().join(format!("bywire-campaign-{}", std::process::id()));
    // The redundant tug's 2-out-of-3 voter is no mechanism of these vehicles' supervisors.
    let supervised = Mechanism::REMOVABLE
        .into_iter()
        .filter(|m| *m != Mechanism::Voter);
    for m in supervised {
        let disabled = Mechanisms::NONE.with(m);
        let results = run(&c, 2, disabled);
        let failed: Vec<&CellResult> = results
            .iter()
            .filter(|r| r.verdict == Verdict::Fail)
            .collect();
        assert!(!failed.is_empty(), "{m} switched off: no cell failed");
        assert!(report::unnoticed(&results, disabled).is_empty(), "{m}");
        // The cells expecting it fail (where they ran).
        assert!(
            failed.iter().any(|r| r.expected.mechanism == Some(m)),
            "{m}: no cell expecting it failed"
        );
        report::write(&dir, &c, &results, disabled, 0.0).unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains(&format!("Switched off in the vehicle's software: {m}")));
        for r in &failed {
            assert!(md.contains(&format!("`{}`", r.name)), "{m}: {}", r.name);
        }
        let junit = std::fs::read_to_string(dir.join("junit.xml")).unwrap();
        assert_eq!(junit.matches("<failure ").count(), failed.len(), "{m}");
    }
    // Switched off, the voter fails nothing here: the run says the campaign does not test it.
    let results = run(&c, 2, Mechanisms::NONE.with(Mechanism::Voter));
    assert_eq!(
        report::unnoticed(&results, Mechanisms::NONE.with(Mechanism::Voter)),
        [Mechanism::Voter]
    );
    std::fs::remove_dir_all(&dir).ok();
}
