"""Line and branch coverage of the safety core from an LCOV file, per file and per crate,
written as summary.json and summary.md; exits 1 below the minimum line coverage.

Usage: coverage_summary.py COVERAGE.lcov OUT_DIR MIN_PERCENT
"""
import glob
import json
import os
import re
import sys

# The code a vehicle runs. Left out, and tested from the command line: the acceptance
# checks, the replay and the fuzz tool of bywire-vehicle.
SCOPE = {
    "bywire-vehicle": [
        f"crates/bywire-vehicle/src/{name}.rs"
        for name in (
            "supervisor ads wire redundancy arbitration backup degradation command "
            "mechanism secured autoware profile profile_wire bindings fail_operational"
        ).split()
    ],
    "bywire-secoc": sorted(glob.glob("crates/bywire-secoc/src/*.rs")),
    "bywire-core (E2E)": sorted(glob.glob("crates/bywire-core/src/e2e/*.rs")),
    "bywire-tug (ECU)": [
        f"crates/bywire-tug/src/{name}.rs"
        for name in ("ecu", "drives", "duplex", "backup_steering", "plausibility", "wire", "secured")
    ],
}


def test_module_start(path):
    """The first line of a unit-test module at the end of the file (not counted)."""
    lines = open(path, encoding="utf-8").read().splitlines()
    for number, (line, after) in enumerate(zip(lines, lines[1:] + [""]), start=1):
        if re.match(r"#\[cfg\(.*\btest\b.*\)\]", line) and after.startswith("mod "):
            return number
    return len(lines) + 1


def read_lcov(path):
    files = {}
    current = None
    for line in open(path, encoding="utf-8"):
        line = line.strip()
        if line.startswith("SF:"):
            current = files.setdefault(os.path.relpath(line[3:]), {"lines": {}, "branches": {}})
        elif line.startswith("DA:") and current is not None:
            number, count = line[3:].split(",")[:2]
            lines = current["lines"]
            lines[int(number)] = lines.get(int(number), 0) + int(count)
        elif line.startswith("BRDA:") and current is not None:
            number, block, branch, taken = line[5:].split(",")
            key = (int(number), block, branch)
            hits = 0 if taken == "-" else int(taken)
            current["branches"][key] = current["branches"].get(key, 0) + hits
    return files


def main():
    lcov, out, minimum = sys.argv[1], sys.argv[2], float(sys.argv[3])
    measured = read_lcov(lcov)
    report = {"minimum_line_percent": minimum, "crates": {}, "files": {}}
    totals = [0, 0, 0, 0]
    for crate, paths in SCOPE.items():
        crate_totals = [0, 0, 0, 0]
        for path in paths:
            data = measured.get(path)
            if data is None and re.search(r"\bfn\s", open(path, encoding="utf-8").read()):
                sys.exit(f"coverage: {path} was not measured (is it built by the tests run?)")
            if data is None:
                continue  # declarations only: no code to run
            end = test_module_start(path)
            lines = {n: c for n, c in data["lines"].items() if n < end}
            branches = {k: c for k, c in data["branches"].items() if k[0] < end}
            figures = [
                sum(1 for c in lines.values() if c > 0),
                len(lines),
                sum(1 for c in branches.values() if c > 0),
                len(branches),
            ]
            report["files"][path] = {
                "lines_covered": figures[0],
                "lines": figures[1],
                "branches_covered": figures[2],
                "branches": figures[3],
                "lines_missed": sorted(n for n, c in lines.items() if c == 0),
            }
            crate_totals = [a + b for a, b in zip(crate_totals, figures)]
        report["crates"][crate] = dict(
            zip(("lines_covered", "lines", "branches_covered", "branches"), crate_totals)
        )
        totals = [a + b for a, b in zip(totals, crate_totals)]
    report["total"] = dict(zip(("lines_covered", "lines", "branches_covered", "branches"), totals))

    def percent(covered, of):
        return 100.0 * covered / of if of else 100.0

    line_percent = percent(totals[0], totals[1])
    report["total"]["line_percent"] = round(line_percent, 2)
    report["total"]["branch_percent"] = round(percent(totals[2], totals[3]), 2)
    md = [
        "| crate | lines | branches |",
        "|---|---|---|",
    ]
    for crate, c in list(report["crates"].items()) + [("**all**", report["total"])]:
        md.append(
            f"| {crate} | {percent(c['lines_covered'], c['lines']):.1f} % "
            f"({c['lines_covered']:,}/{c['lines']:,}) | "
            f"{percent(c['branches_covered'], c['branches']):.1f} % "
            f"({c['branches_covered']:,}/{c['branches']:,}) |"
        )
    os.makedirs(out, exist_ok=True)
    for name, text in (
        ("summary.json", json.dumps(report, indent=2)),
        ("summary.md", "\n".join(md) + "\n"),
    ):
        with open(os.path.join(out, name + ".tmp"), "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(os.path.join(out, name + ".tmp"), os.path.join(out, name))
    print("\n".join(md))
    if line_percent < minimum:
        sys.exit(f"coverage: {line_percent:.2f} % of lines, below the gate of {minimum} %")


main()
