"""Check that the outputs of four reference trials are byte-identical to the recorded ones.

The trials: the default emulated trial (``hil run --speed max --viewer none``: deterministic at any
speed, since the recording's order decides), the paper scenario (``hil simulate
configs/liu2019_sim.yaml``), a simulated calibration (``hil calibrate configs/calibration_short.yaml
--simulate``) and a noise run (``hil noise configs/noise_static.yaml``). Each file is compared without its
``record`` (who, when, where: a run's own) and, for the default trial, without ``streams.sync.confirmed_at_s``
(when the pairing was confirmed depends on how the bytes were read at ``--speed max``; the samples do not).
The reference digests in ``outputs_reference.json`` were recorded on this project's reference machine (2
cores, x86-64, the numpy of ``pyproject.toml``'s lower bounds or later); another machine's BLAS may round
differently, so record its own with ``--record`` before a change and compare after it.

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
TRIALS = {  # name: (the command's arguments, the files compared)
    "default_trial": (["run", "--speed", "max", "--viewer", "none", "--quiet", "--no-figures"],
                      ("result.json", "series.csv")),
    "liu2019_sim": (["simulate", "configs/liu2019_sim.yaml", "--viewer", "none", "--no-figures"],
                    ("result.json", "series.csv")),
    "calibration": (["calibrate", "configs/calibration_short.yaml", "--simulate", "--viewer", "none", "--no-figures"],
                    ("result.json", "calibration.json")),
    "noise": (["noise", "configs/noise_static.yaml", "--no-figures"], ("noise.json",)),
}
UNSTABLE = {"default_trial": ("streams", "sync", "confirmed_at_s")}  # see above


def _comparable(path: Path, unstable: tuple[str, ...] | None) -> bytes:
    """The file's bytes; a JSON document's as written without its ``record`` and the ``unstable`` key."""
    if path.suffix != ".json":
        return path.read_bytes()
    doc = json.loads(path.read_text())
    doc.pop("record", None)
    if unstable is not None:
        *blocks, last = unstable
        node = doc
        for block in blocks:
            node = node.get(block) or {}
        node.pop(last, None)
    return (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode()


def digests() -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (args, files) in TRIALS.items():
            run_dir = Path(tmp) / name
            subprocess.run([sys.executable, "-m", "hil.cli", *args, "--out", str(run_dir), "--no-history"],
                           check=False, cwd=HERE.parent, stdout=subprocess.DEVNULL)
            out[name] = {f: hashlib.sha256(_comparable(run_dir / f, UNSTABLE.get(name))).hexdigest() for f in files}
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
