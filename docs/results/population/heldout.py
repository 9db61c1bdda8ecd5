"""Issue 63's held-out comparison: the population's walkers (``six/<treatment>/policies/trial_K``) and the run
alone's (``alone/cppn-map/...``) walked in ONE ``evaluate`` run (``benchmarks/device/heldout.sh``: suite v1, the base
policy beside them, every walker with the same key), split into the per-treatment folders ``generalise`` reads.

    python docs/results/population/heldout.py runs/pop_heldout runs/pop_split
    python -m experiments generalise runs/pop_split/six alone=runs/pop_split/alone/cppn-map \\
        --base runs/pop_heldout/fitness.csv --out runs/pop_split/generalisation

For each treatment folder whose walkers are in ``EVAL/fitness.csv`` (or ``fitness.csv.gz``), writes
``OUT/<run>/<treatment>/heldout/fitness.csv`` (the base policy's rows, then that treatment's walkers' rows, as
``evaluate`` wrote them) and copies the treatment's ``summary.json`` beside it. A walker row's ``policy`` is the path
given to ``evaluate``, ``.../<run>/<treatment>/policies/trial_K``; the treatment folder is read from it relative
to this script's folder (``docs/results/population/``), so the split works wherever the evaluation ran.
"""

from __future__ import annotations

import csv
import gzip
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _open(path: Path):
    return gzip.open(path, "rt", newline="") if path.suffix == ".gz" else open(path, newline="")


def treatment_of(policy: str) -> tuple[str, str] | None:
    """``(run, treatment)`` of a walker row's ``policy`` (``.../<run>/<treatment>/policies/trial_K``); None for the
    base policy's rows."""
    parts = Path(policy).parts
    if len(parts) < 4 or parts[-2] != "policies" or not parts[-1].startswith("trial_"):
        return None
    return parts[-4], parts[-3]


def split(evaluation: Path, out: Path) -> dict[tuple[str, str], int]:
    """Write the per-treatment ``heldout/fitness.csv`` and ``summary.json`` under ``out``; returns the walkers per
    ``(run, treatment)``. ValueError for a walker whose treatment folder has no ``summary.json`` here."""
    path = evaluation / "fitness.csv"
    path = path if path.is_file() else path.with_suffix(".csv.gz")
    with _open(path) as f:
        reader = csv.DictReader(f)
        header, rows = reader.fieldnames, list(reader)
    base = [r for r in rows if treatment_of(r["policy"]) is None]
    groups: dict[tuple[str, str], list] = {}
    for r in rows:
        key = treatment_of(r["policy"])
        if key is not None:
            groups.setdefault(key, []).append(r)
    walkers = {}
    for (run, treatment), mine in sorted(groups.items()):
        summary = HERE / run / treatment / "summary.json"
        if not summary.is_file():
            raise ValueError(f"{path}: walkers of {run}/{treatment}, but {summary} does not exist")
        folder = out / run / treatment
        (folder / "heldout").mkdir(parents=True, exist_ok=True)
        with open(folder / "heldout" / "fitness.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=header)
            w.writeheader()
            w.writerows(base + mine)
        shutil.copy(summary, folder / "summary.json")
        walkers[(run, treatment)] = len({r["policy"] for r in mine})
    return walkers


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: heldout.py EVALUATION_FOLDER OUT_FOLDER", file=sys.stderr)
        return 2
    for (run, treatment), n in split(Path(argv[0]), Path(argv[1])).items():
        print(f"{run}/{treatment}: {n} walkers")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
