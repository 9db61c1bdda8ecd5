"""Seconds per chunk of the whole runs `six`, `alone` and `split`, read back from their logs (logs/gpu1.log.gz: six on
GPU 1; logs/gpu0.log.gz: alone on GPU 0, then Experiment 4's ant archives; logs/split.log.gz: the two processes of
`split`, one per GPU, whose lines interleave and name no process: each line goes to the process whose trials' mean
hardest cell after that chunk, from their history.csv, is the one the line prints).

    python docs/results/population/chunk_times.py

A run prints ``<name>: chunk C of 75, ..., S s/chunk`` where S is the command's running mean (its elapsed time over
the chunks it has done, its first chunk included, rounded to 0.1 s). Each command (a new ``environment`` line)
restarts it. Per command this prints the chunks it ran, its elapsed time and the mean of its chunks after the
first (the first holds a cold compile or a resume's first call); then the mean over every command's chunks but its
first, weighted by chunks: the figure benchmarks/RESULTS.md gives. The rounding bounds each command's elapsed
time to within 0.05 s x its chunks.
"""

from __future__ import annotations

import csv
import gzip
import json
import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = {"six": ("gpu1.log.gz", r"population 1: chunk (\d+) of \d+.*?, ([\d.]+) s/chunk"),
        "alone": ("gpu0.log.gz", r"cppn map: chunk (\d+) of \d+.*?, ([\d.]+) s/chunk")}
SPLIT = ("split.log.gz", r"population 1: chunk (\d+) of \d+, hardest ([\d.]+) cells.*?, ([\d.]+) s/chunk")


def split_hardest() -> list[dict[int, float]]:
    """Per process of ``split`` (``split<I>of<N>.json``: its treatments, on GPU I), the mean hardest cell of its
    trials after each chunk (1-based, as the log prints it), from the treatments' ``history.csv``."""
    out = []
    for shard in sorted(HERE.glob("split*of*.json")):
        rows: dict[int, list[float]] = {}
        for name in json.loads(shard.read_text())["treatments"]:
            with open(HERE / "split" / name.replace(" ", "-") / "history.csv") as f:
                for r in csv.DictReader(f):
                    rows.setdefault(int(r["chunk"]) + 1, []).append(float(r["hardest"]))
        out.append({c: sum(v) / len(v) for c, v in rows.items()})
    return out


def tracks(lines: list[tuple[int, float, float]], hardest: list[dict[int, float]]) -> list[list[tuple[int, float]]]:
    """The processes' ``(chunk, hardest, running s/chunk)`` lines of one command, interleaved, apart: each line joins
    the process whose trials' mean hardest cell after that chunk (:func:`split_hardest`) is the line's."""
    out: list[list[tuple[int, float]]] = [[] for _ in hardest]
    for c, h, s in lines:
        k = min(range(len(hardest)), key=lambda k: abs(hardest[k].get(c, float("inf")) - h))
        out[k].append((c, s))
    return out


def commands(path: Path, pattern: str) -> list[list[tuple]]:
    """Per command of the log: its ``(chunk, running s/chunk)`` lines (or the pattern's groups) in order."""
    out: list[list[tuple]] = [[]]
    for line in gzip.open(path, "rt"):
        if "environment {" in line and out[-1]:
            out.append([])
        m = re.search(pattern, line)
        if m:
            out[-1].append((int(m.group(1)), *map(float, m.groups()[1:])))
    return [c for c in out if c]


def report(run: str, runs: list[list[tuple[int, float]]]) -> None:
    """Print each command's chunks and the mean over every command's chunks but its first."""
    total_s = total_n = 0.0
    start = 0  # the chunk the previous command ended at
    for lines in runs:
        end, mean = lines[-1]
        first = next(iter(lines))  # the command's first printed chunk
        done = end - start  # chunks this command ran
        elapsed = mean * done
        # the first chunk's time: its running mean when it is the first chunk printed, else not separable
        first_s = first[1] if first[0] == start + 1 else None
        if first_s is not None:
            total_s += elapsed - first_s
            total_n += done - 1
        tail = f", chunks {start + 2}-{end}: {(elapsed - first_s) / (done - 1):.2f} s each" if first_s else \
            " (its first chunk not printed alone: left out of the mean)"
        print(f"{run}: chunks {start + 1}-{end} in {elapsed:.1f} s{tail}")
        start = end
    print(f"{run}: {total_s / total_n:.2f} s a chunk over {int(total_n)} chunks (every command's first left out)")


def main() -> None:
    for run, (log, pattern) in RUNS.items():
        report(run, commands(HERE / "logs" / log, pattern))
    log, pattern = SPLIT
    if (HERE / "logs" / log).exists():
        hardest = split_hardest()
        per = [tracks(c, hardest) for c in commands(HERE / "logs" / log, pattern)]
        for k in range(len(hardest)):
            report(f"split, GPU {k}", [c[k] for c in per])

if __name__ == "__main__":
    main()
