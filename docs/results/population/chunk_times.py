"""Seconds per chunk of the whole runs `six`, `alone` and `split`, read back from their logs (logs/gpu1.log.gz: six on
GPU 1; logs/gpu0.log.gz: alone on GPU 0, then Experiment 4's ant archives; logs/split.log.gz: the two processes of
`split`, one per GPU, whose lines interleave: each line goes to the process whose last printed chunk is below its
own and nearest, of two as near the one whose last printed hardest cell is nearest).

    python docs/results/population/chunk_times.py

A run prints ``<name>: chunk C of 75, ..., S s/chunk`` where S is the command's running mean (its elapsed time over
the chunks it has done, its first chunk included, rounded to 0.1 s). Each command (a new ``environment`` line)
restarts it. Per command this prints the chunks it ran, its elapsed time and the mean of its chunks after the
first (the first holds a cold compile or a resume's first call); then the mean over every command's chunks but its
first, weighted by chunks: the figure benchmarks/RESULTS.md gives. The rounding bounds each command's elapsed
time to within 0.05 s x its chunks.
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = {"six": ("gpu1.log.gz", r"population 1: chunk (\d+) of \d+.*?, ([\d.]+) s/chunk"),
        "alone": ("gpu0.log.gz", r"cppn map: chunk (\d+) of \d+.*?, ([\d.]+) s/chunk")}
SPLIT = ("split.log.gz", r"population 1: chunk (\d+) of \d+, hardest ([\d.]+) cells.*?, ([\d.]+) s/chunk", 2)


def tracks(lines: list[tuple[int, float, float]], n: int) -> list[list[tuple[int, float]]]:
    """``n`` processes' ``(chunk, hardest, running s/chunk)`` lines of one command, interleaved, apart: each line joins
    the process whose last chunk is below the line's and nearest to it, of two as near the one whose last hardest
    cell is nearest."""
    out: list[list[tuple[int, float, float]]] = [[] for _ in range(n)]
    for line in lines:
        free = [t for t in out if not t or t[-1][0] < line[0]]
        best = min(free, key=lambda t: (line[0] - t[-1][0], abs(t[-1][1] - line[1])) if t else (0, 0.0))
        best.append(line)
    return [[(c, s) for c, _, s in t] for t in out]


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
    log, pattern, n = SPLIT
    if (HERE / "logs" / log).exists():
        per = [tracks(c, n) for c in commands(HERE / "logs" / log, pattern)]
        for k in range(n):
            report(f"split, process {k}", [c[k] for c in per])


if __name__ == "__main__":
    main()
