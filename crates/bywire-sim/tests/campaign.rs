//! The default campaign (`campaigns/default.toml`): every cell executed passes or does not
//! apply with its reason, the same whatever the number of threads; and with each mechanism the
//! vehicle's software has switched off, cells fail and the report says so.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::collections::BTreeSet;
use std::path::Path;

use bywire_sim::campaign::{self, report, Campaign, CellResult, FaultClass, Model, Verdict};
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

fn default_campaign() -> Campaign {
    Campaign::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../campaigns/default.toml"))
        .unwrap()
}

/// The campaign on the profiles of one model only.
fn only(c: &Campaign, model: Model) -> Campaign {
    let mut c = c.clone();
    c.profiles.retain(|p| p.model == model);
    c
}

fn run(c: &Campaign, jobs: usize, disabled: Mechanisms) -> Vec<CellResult> {
    campaign::run(c, jobs, disabled, &|_| {}).unwrap()
}

/// Verifies: REQ-FI-1, REQ-CAN-1
#[test]
fn the_default_campaign_passes_every_cell_it_can_run_on_four_vehicles() {
    let c = default_campaign();
    let results = run(&c, 2, Mechanisms::NONE);
    let failed: Vec<String> = results
        .iter()
        .filter(|r| r.verdict == Verdict::Fail)
        .map(|r| format!("{}: {}", r.name, r.why))
        .collect();
    assert!(failed.is_empty(), "{failed:#?}");
    // Every fault class, on four vehicles (the plain tug's two-bus and secured variants and
    // the shuttle on the plant model, the whole redundant tug), in five states.
    let classes: BTreeSet<FaultClass> = c.faults.iter().map(|f| f.class).collect();
    assert_eq!(classes.len(), FaultClass::ALL.len());
    assert!(classes.len() >= 20);
    let profiles: BTreeSet<&str> = results.iter().map(|r| r.profile.as_str()).collect();
    assert_eq!(profiles.len(), 4);
    assert_eq!(results.len(), 4 * 5 * c.faults.len());
    // A cell that does not apply says why; one that passes was watched.
    for r in &results {
        match r.verdict {
            Verdict::NotApplicable => assert!(!r.why.is_empty(), "{}", r.name),
            _ => assert!(r.why.is_empty(), "{}", r.name),
        }
    }
    // Every mechanism is expected by some executed cell.
    let expected: BTreeSet<Mechanism> = results
        .iter()
        .filter(|r| r.verdict == Verdict::Pass)
        .filter_map(|r| r.expected.mechanism)
        .collect();
    for m in Mechanism::ALL {
        assert!(expected.contains(&m), "no cell expects {m}");
    }
    // Deterministic: one thread gives the same cells (the plant model's: the whole tug's
    // determinism is its own tests').
    let plant = only(&c, Model::Plant);
    let results: Vec<CellResult> = results
        .into_iter()
        .filter(|r| plant.profiles.iter().any(|p| p.label() == r.profile))
        .collect();
    let again = run(&plant, 1, Mechanisms::NONE);
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
    for m in Mechanism::REMOVABLE {
        let disabled = Mechanisms::NONE.with(m);
        // The voter is the whole tug's; the others the supervisor's, on the plant model.
        let model = match m {
            Mechanism::Voter => Model::Tug,
            _ => Model::Plant,
        };
        let c = only(&c, model);
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
    // A campaign without the voter's faults cannot tell it missing, and says so.
    let mut small = c.clone();
    small.faults.retain(|f| f.class == FaultClass::NodeSilent);
    let voter = Mechanisms::NONE.with(Mechanism::Voter);
    let results = run(&small, 2, voter);
    assert_eq!(report::unnoticed(&results, voter), [Mechanism::Voter]);
    std::fs::remove_dir_all(&dir).ok();
}
