"""How far every number of the two reference trials moved against another revision of the project.

For a change that is mathematically equivalent but rounds differently (summation order, fused
multiply-add in BLAS against written-out products) ``outputs_unchanged.py`` reports DIFFERENT; this
script says by how much. It runs the trials of ``outputs_unchanged.py`` on this tree and on REV (a
git revision, exported to a temporary directory), compares result.json and series.csv number by
number, and passes when every number moved by less than ``--rel`` relative or ``--abs`` absolute and
every other value (flags, ranks, counts, convergence times, empty cells) is equal.

    .venv/bin/python benchmarks/outputs_diff.py main     # exit 1 when some number moved further
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

from outputs_unchanged import TRIALS

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def run_trials(tree: Path, out: Path, trials: dict[str, list[str]]) -> None:
    for name, args in trials.items():
        subprocess.run([sys.executable, "-m", "hil.cli", *args, "--out", str(out / name)], check=False, cwd=tree,
                       stdout=subprocess.DEVNULL)  # fmt: skip


def leaves(value: object, path: str = "") -> dict[str, object]:
    """Every scalar of a JSON document by its path."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in leaves(item, f"{path}/{key}").items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in leaves(item, f"{path}[{i}]").items()}
    return {path: value}


def series_cells(path: Path) -> dict[str, str]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    return {f"row {r} {header[c]}": cell for r, row in enumerate(rows[1:], 1) for c, cell in enumerate(row)}


def _number(value: object) -> float | None:
    if isinstance(value, bool) or value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def compare(old: dict[str, object], new: dict[str, object], rel: float, tol_abs: float, exact: set[str]
            ) -> tuple[int, int, float, list[str]]:
    """(changed numbers, failures, largest relative move, failure descriptions)."""
    changed, worst, failures = 0, 0.0, []
    for key in sorted(old.keys() | new.keys()):
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        x, y = _number(a), _number(b)
        column = key.split(" ")[-1].split("/")[-1]
        if x is None or y is None or column in exact or (math.isnan(x) != math.isnan(y)):
            failures.append(f"{key}: {a!r} -> {b!r}")
            continue
        changed += 1
        move = abs(x - y)
        relative = move / max(abs(x), abs(y))
        worst = max(worst, relative)
        if relative >= rel and move >= tol_abs:
            failures.append(f"{key}: {a!r} -> {b!r} (relative {relative:.1e})")
    return changed, len(failures), worst, failures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("rev", help="the git revision to compare against, e.g. main")
    parser.add_argument("--rel", type=float, default=1e-9, help="largest relative move allowed")
    parser.add_argument("--abs", type=float, default=1e-12, help="an absolute move below this is allowed too")
    parser.add_argument("--trial", choices=sorted(TRIALS), action="append", help="only this trial (repeatable)")
    args = parser.parse_args()
    trials = {name: TRIALS[name] for name in args.trial or TRIALS}
    exact = {"samples", "observable", "gram_rank", "gram_rank_9"}  # decisions and counts: never move
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        base, old_out, new_out = Path(tmp) / "base", Path(tmp) / "old", Path(tmp) / "new"
        base.mkdir()
        archive = subprocess.run(["git", "archive", args.rev], cwd=ROOT, check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        run_trials(base, old_out, trials)
        run_trials(ROOT, new_out, trials)
        for name in trials:
            old_json = leaves(json.loads((old_out / name / "result.json").read_text()))
            new_json = leaves(json.loads((new_out / name / "result.json").read_text()))
            json_exact = {k.split("/")[-1] for k in old_json if not isinstance(old_json[k], float)}
            for label, old, new, keys in (
                ("result.json", old_json, new_json, json_exact),
                ("series.csv", series_cells(old_out / name / "series.csv"),
                 series_cells(new_out / name / "series.csv"), exact),
            ):
                changed, failed, worst, failures = compare(old, new, args.rel, args.abs, keys)
                bad += failed
                print(f"{name:15s} {label:12s} {changed:6d} numbers changed, largest relative move {worst:.1e},"
                      f" {failed} beyond the tolerance")  # fmt: skip
                for line in failures[:20]:
                    print(f"    {line}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
