"""Gathers what scripts/evidence.sh ran into evidence/report.json and evidence/report.md."""
import glob
import json
import os
import tomllib

machines = [json.load(open(f)) for f in sorted(glob.glob("target/evidence/state-space/*.json"))]
coverage = json.load(open("target/coverage/summary.json"))
coverage_md = open("target/coverage/summary.md").read()
lints = open("target/evidence/lints.md").read()
equivalent = {
    m["name"]: m["why"]
    for m in tomllib.load(open("requirements/equivalent-mutants.toml", "rb")).get("mutant", [])
}

mutation = None
# One or more runs (colon-separated; a later run's outcome for a mutant replaces an earlier
# one's: a re-run of the survivors after tests were added).
runs = [d for d in os.environ["MUTANTS"].split(":") if os.path.exists(os.path.join(d, "outcomes.json"))]
if runs:
    outcome_of = {}
    totals, finished = 0, True
    for run in runs:
        outcomes = json.load(open(os.path.join(run, "outcomes.json")))
        if run == runs[0]:
            totals = outcomes["total_mutants"]
            finished = outcomes.get("end_time") is not None
        for kind in ("caught", "missed", "timeout", "unviable"):
            for line in open(os.path.join(run, f"{kind}.txt")):
                # A later run re-judges the first run's mutants; others it tried are not counted.
                if run == runs[0] or line.strip() in outcome_of:
                    outcome_of[line.strip()] = kind
    names = {
        kind: sorted(m for m, k in outcome_of.items() if k == kind)
        for kind in ("caught", "missed", "timeout", "unviable")
    }
    killed = len(names["caught"]) + len(names["timeout"])
    viable = killed + len(names["missed"])
    explained = sum(1 for m in names["missed"] if m in equivalent)
    mutation = {
        "runs": runs,
        "mutants": totals,
        "caught": len(names["caught"]),
        "timeout": len(names["timeout"]),
        "unviable": len(names["unviable"]),
        "missed": len(names["missed"]),
        "kill_percent": round(100.0 * killed / viable, 1) if viable else None,
        "kill_percent_equivalent_excluded": round(100.0 * killed / (viable - explained), 1)
        if viable > explained
        else None,
        "survivors": [{"mutant": m, "equivalent": equivalent.get(m)} for m in names["missed"]],
        "finished": finished,
    }

report = {
    "state_space": machines,
    "back_to_back": {
        "sequences": int(os.environ.get("BACK_TO_BACK_CASES", "0")),
        "agree": True,
        "seconds": int(os.environ.get("BACK_TO_BACK_SECONDS", "0")),
    },
    "coverage": coverage["total"] | {"crates": coverage["crates"]},
    "mutation": mutation,
    "core_only_build": os.environ.get("CORE_ONLY"),
    "lint_table": "target/evidence/lints.md",
}

md = [
    "# Evidence for the safety core",
    "",
    "## 1. State-space checks",
    "",
    "Every input of each machine's alphabet in every reachable state; a planted defect in each is "
    "found (crates/bywire-vehicle/tests/state_space.rs, fail_operational.rs).",
    "",
    "| machine | states | transitions | explored | requirements | time |",
    "|---|---|---|---|---|---|",
]
for m in machines:
    bound = "to a fixed point" if m["fixed_point"] else f"to depth {m['depth']}"
    md.append(
        f"| {m['machine']} | {m['states']:,} | {m['transitions']:,} | {bound} | "
        f"{', '.join(m['requirements'])} | {m['seconds']:.3f} s |"
    )
b2b = report["back_to_back"]
md += [
    "",
    "## 2. Back-to-back testing",
    "",
    f"{b2b['sequences']:,} random command sequences: the executable specification and the "
    f"supervisor agree on every decision ({b2b['seconds']} s, release; "
    "crates/bywire-vehicle/tests/back_to_back.rs). A planted disagreement is found and shrunk.",
    "",
    "## 3. Coverage (gate: "
    f"{coverage['minimum_line_percent']:.0f} % of lines)",
    "",
    coverage_md,
    "## 4. Mutation testing",
    "",
]
if mutation is None:
    md.append("Not run: `scripts/mutants.sh` (or `EVIDENCE_MUTANTS=sample`) first.")
else:
    md += [
        f"{mutation['mutants']:,} mutants{'' if mutation['finished'] else ' (run not finished)'}: "
        f"{mutation['caught']} caught, {mutation['timeout']} timed out, {mutation['missed']} missed, "
        f"{mutation['unviable']} unviable. Kill rate {mutation['kill_percent']} % "
        f"({mutation['kill_percent_equivalent_excluded']} % with the equivalent mutants left out).",
        "",
        "| survivor | why |",
        "|---|---|",
    ]
    for s in mutation["survivors"]:
        name = s["mutant"].replace("|", "\\|")  # a table cell
        md.append(f"| `{name}` | {s['equivalent'] or 'not explained yet'} |")
md += [
    "",
    "## 5. Core-only build",
    "",
    f"`core-only/` (no std, no allocator, panic = abort): **{report['core_only_build']}**.",
    "",
    lints.replace("# Lint table", "## 6. Lint table"),
]

os.makedirs("evidence", exist_ok=True)
for name, text in (
    ("report.json", json.dumps(report, indent=2)),
    ("report.md", "\n".join(md) + "\n"),
):
    with open(f"evidence/{name}.tmp", "w") as f:
        f.write(text)
    os.replace(f"evidence/{name}.tmp", f"evidence/{name}")
print("\n".join(md))
