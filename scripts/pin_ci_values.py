#!/usr/bin/env python3
"""Writes tests/data/ci_values.toml: what every bundled case the tests run computes today at its CI
resolution, in f64 and in f32, on the CPU backend.

    cargo build --release && scripts/pin_ci_values.py [--bin target/release/pairsum] [--from DIR]

tests/cases.rs and tests/paper_cases.rs hold each result to its f64 value within a band: three
times the change from f64 to f32 (the spread that rounding alone makes in that run), and at least
1e-3 of the value. So a change of summation order passes and a change of the model does not; the
accuracy against each reference is a claim of the docs (README.md, docs/results/), with its
convergence data, not of this file.

Run it after a change that is meant to move a case's figures, and review the diff of the file as
you would review code: every changed number is a changed result. `--from DIR` reuses the runs an
earlier call left in DIR (each run's report.json) instead of running again.
"""
import argparse
import json
import math
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (case or study, its --set values): exactly the runs of tests/cases.rs and tests/paper_cases.rs.
RUNS = [
    ("elastic_wave", {}),
    ("colliding_bars_1d", {}),
    ("standing_wave", {}),
    ("cantilever", {}),
    ("cantilever_lsm", {}),
    ("cantilever_2d", {}),
    ("cantilever_3d", {}),
    ("clamped_plate_2d", {}),
    ("sod_shock_tube", {}),
    ("poiseuille_2d", {}),
    ("sod_shock_tube", {"model": "models::ideal_gas_switch"}),
    ("beam_vibration_2d", {}),
    ("dam_break_2d", {"boundary": "dbc"}),
    ("dam_break_2d", {"boundary": "adami"}),
    ("dam_break_3d", {}),
    ("hydrostatic_tank", {"boundary": "dbc"}),
    ("hydrostatic_tank", {"boundary": "adami"}),
    ("piston_2d", {"boundary": "dbc"}),
    ("piston_2d", {"boundary": "adami"}),
    ("body_in_water_2d", {}),
    ("water_jet_plate_2d", {}),
    ("water_on_plate_tl_2d", {}),
    ("rings_2d", {}),
    ("hypervelocity_impact", {}),
    ("hypervelocity_impact", {"damage_length": "2"}),
    ("taylor_bar", {}),
    ("taylor_bar_copper", {}),
    ("borvik_8mm", {}),
    ("borvik_perforation", {"damage_length": "2"}),
    ("tensile_artificial_stress", {}),
    ("cube_on_cube_cspm", {}),
    ("sphere_plate_graded_study", {}),
    ("fans_bullet_study", {}),
    ("taylor_bar_axisymmetric", {}),
    ("borvik_axisymmetric", {}),
    ("hypervelocity_impact_axisymmetric", {}),
]


def is_timing(quantity):
    """A result measured with the clock (a study's speed-up): not a figure of the computation, so
    never pinned. tests/common/mod.rs (`is_timing`) applies the same rule."""
    return "speed-up" in quantity


def tag(case, sets):
    return "-".join([case] + [f"{k}={v}" for k, v in sorted(sets.items())])


def run(binary, case, sets, precision, out):
    args = [binary, "run", case, "--backend", "cpu", "--precision", precision, "--quiet", "--force"]
    for k, v in sets.items():
        args += ["--set", f"{k}={v}"]
    args += ["--out", str(out)]
    done = subprocess.run(args, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(map(str, args))} failed:\n{done.stderr}")


def results(out):
    report = json.loads((out / "report.json").read_text())
    return {r["quantity"]: r["value"] for r in report["results"]}


def toml_string(s):
    return json.dumps(s, ensure_ascii=False)


def pin_lines(case, sets, both, bands):
    """The [[pin]] tables of one run: each result's f64 and f32 values and its band (given, for
    kept pins, or computed)."""
    lines = []
    for quantity, v64 in both["f64"].items():
        if is_timing(quantity):
            continue
        v32 = both["f32"].get(quantity)
        if v64 is None or v32 is None or not (math.isfinite(v64) and math.isfinite(v32)):
            sys.exit(f"{tag(case, sets)}: `{quantity}` is {v64} in f64 and {v32} in f32: nothing to pin")
        band = bands.get(quantity, max(3.0 * abs(v32 - v64), 1e-3 * abs(v64)))
        sets_toml = ", ".join(f"{k} = {toml_string(v)}" for k, v in sorted(sets.items()))
        lines += [
            "[[pin]]",
            f"case = {toml_string(case)}",
            f"set = {{ {sets_toml} }}" if sets else "set = {}",
            f"quantity = {toml_string(quantity)}",
            f"f64 = {v64!r}",
            f"f32 = {v32!r}",
            f"band = {band!r}",
            "",
        ]
    return lines


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", default=str(ROOT / "target/release/pairsum"))
    p.add_argument("--from", dest="source", help="reuse the runs in this folder")
    p.add_argument(
        "--only",
        nargs="+",
        metavar="CASE",
        help="run only these cases; keep every other case's pins as tests/data/ci_values.toml has them",
    )
    a = p.parse_args()
    kept = {}
    if a.only:
        for pin in tomllib.loads((ROOT / "tests/data/ci_values.toml").read_text())["pin"]:
            kept.setdefault(tag(pin["case"], pin["set"]), []).append(pin)
    work = Path(a.source) if a.source else Path(tempfile.mkdtemp(prefix="pairsum-pins-"))
    lines = [
        "# What each bundled case computes today at its CI resolution, on the CPU backend: written by",
        "# scripts/pin_ci_values.py, read by tests/cases.rs and tests/paper_cases.rs. A regression band,",
        "# not an accuracy claim: `band` = max(3 |f32 - f64|, 1e-3 |f64|), the spread rounding alone",
        "# makes in that run. Timings (a study's speed-ups) are not pinned. Review a change of this",
        "# file as a change of results.",
        "",
    ]
    for case, sets in RUNS:
        if a.only and case not in a.only:
            pins = kept.get(tag(case, sets), [])  # none: the run reports no results (rings_2d)
            both = {"f64": {p["quantity"]: p["f64"] for p in pins}, "f32": {p["quantity"]: p["f32"] for p in pins}}
            lines += pin_lines(case, sets, both, {p["quantity"]: p["band"] for p in pins})
            continue
        both = {}
        for precision in ["f64", "f32"]:
            out = work / f"{tag(case, sets)}-{precision}"
            if not a.source:
                print(f"{tag(case, sets)} {precision}", file=sys.stderr)
                run(a.bin, case, sets, precision, out)
            both[precision] = results(out)
        lines += pin_lines(case, sets, both, {})
    target = ROOT / "tests/data/ci_values.toml"
    target.write_text("\n".join(lines))
    print(f"wrote {target} (runs in {work})", file=sys.stderr)


if __name__ == "__main__":
    main()
