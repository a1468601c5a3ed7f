"""Check that result.json and series.csv of two reference trials are byte-identical to the recorded ones.

The trials: the default emulated trial (``hil run --speed max --viewer none``: deterministic at any
speed, since the recording's order decides) and the paper scenario (``hil simulate
configs/liu2019_sim.yaml``). The reference digests in ``outputs_reference.json`` were recorded on this
project's reference machine (2 cores, x86-64, the numpy of ``pyproject.toml``'s lower bounds or later);
another machine's BLAS may round differently, so record its own with ``--record`` before a change and
compare after it.

    .venv/bin/python benchmarks/outputs_unchanged.py            # compare; exit 1 on a difference
    .venv/bin/python benchmarks/outputs_unchanged.py --record   # write outputs_reference.json anew
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REFERENCE = HERE / "outputs_reference.json"
TRIALS = {
    "default_trial": ["run", "--speed", "max", "--viewer", "none", "--quiet", "--no-figures"],
    "liu2019_sim": ["simulate", "configs/liu2019_sim.yaml", "--viewer", "none", "--no-figures"],
}
FILES = ("result.json", "series.csv")


def _without_record(path: Path) -> bytes:
    """The file's bytes; result.json's as written without its ``record`` (who, when, where: a run's own)."""
    if path.name != "result.json":
        return path.read_bytes()
    from hil.outputs.result import write_result

    doc = json.loads(path.read_text())
    doc.pop("record", None)
    write_result(path.parent, doc)
    return path.read_bytes()


def digests() -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, args in TRIALS.items():
            run_dir = Path(tmp) / name
            subprocess.run([sys.executable, "-m", "hil.cli", *args, "--out", str(run_dir)], check=False,
                           cwd=HERE.parent, stdout=subprocess.DEVNULL)
            out[name] = {f: hashlib.sha256(_without_record(run_dir / f)).hexdigest() for f in FILES}
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--record", action="store_true", help="write the reference digests anew")
    args = parser.parse_args()
    now = digests()
    if args.record:
        REFERENCE.write_text(json.dumps(now, indent=2) + "\n")
        print(f"recorded {REFERENCE}")
        return 0
    reference = json.loads(REFERENCE.read_text())
    differ = 0
    for name, files in now.items():
        for f, digest in files.items():
            same = reference[name][f] == digest
            differ += not same
            print(f"{name:15s} {f:12s} {'identical' if same else 'DIFFERENT'}  {digest[:16]}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
