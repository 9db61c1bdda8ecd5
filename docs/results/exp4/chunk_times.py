"""Seconds per chunk of Experiment 4's humanoid training, read back from the device logs (logs/OBS_gpu0.log.gz:
GPU 0, `train humanoid OBS --shard 0/2`: the mixed and steps map treatments as one 20-trial population, then
terrain levels alone, 10 trials; logs/OBS_gpu1.log.gz: GPU 1, `--shard 1/2`: DR and PLR as one 20-trial
population). 2 x H200, MuJoCo Warp with the heightfield patch, 2026-11-30: OBS blind at commit 2117dc4, perceptive
at a514649.

    python docs/results/exp4/chunk_times.py [blind|perceptive]   # default: both

A population prints ``population K: chunk C of 75, ... (mean of T trials, ...), S s/chunk`` at most every 10 s, S
the command's running mean over the chunks it has done (rounded to 0.1 s); a command that resumes a population says
``resuming <treatment> at chunk N``, so its chunks start at N + 1 (a command may end after chunks it did not
print). A new command starts at ``pair.sh``'s ``+ python`` echo. The populations' lines are told apart by their
trial count T (20: a pair of treatments, 10: terrain levels alone). Per command this leaves out the first printed
group of chunks (a cold first chunk holds MuJoCo Warp's kernel builds: 72-93 s; a resumed command's first group
took 4-6 s more than its other chunks) and prints the mean of the rest; then the mean over the commands, weighted
by chunks.
"""

from __future__ import annotations

import gzip
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CHUNK = r"population \d+: chunk (\d+) of \d+, hardest [\d.]+ cells \(mean of {trials} trials.*?([\d.]+) s/chunk"
RESUME = r"population \d+: resuming {name} at chunk (\d+) of"
RUNS = {"GPU 0: mixed map + steps map (20 trials)": ("gpu0", 20, "mixed map"),
        "GPU 0: mixed levels alone (10 trials)": ("gpu0", 10, "mixed levels"),
        "GPU 1: mixed DR + mixed PLR (20 trials)": ("gpu1", 20, "mixed dr")}


def commands(path: Path, trials: int, name: str) -> list[tuple[int, list[tuple[int, float]]]]:
    """Per command of the log that ran this population: ``(the chunk it started after, its (chunk, running s/chunk)
    lines)``."""
    chunk, resume = re.compile(CHUNK.format(trials=trials)), re.compile(RESUME.format(name=re.escape(name)))
    out: list[list] = [[0, []]]
    for line in gzip.open(path, "rt"):
        if line.startswith("+ python"):
            out.append([0, []])
        elif m := resume.search(line):
            out[-1][0] = int(m.group(1))
        elif m := chunk.search(line):
            out[-1][1].append((int(m.group(1)), float(m.group(2))))
    return [(start, lines) for start, lines in out if lines]


def main(observations: list[str]) -> None:
    for obs in observations:
        for label, (gpu, trials, name) in RUNS.items():
            report(f"{obs}, {label}", HERE / "logs" / f"{obs}_{gpu}.log.gz", trials, name)


def report(label: str, log: Path, trials: int, name: str) -> None:
    """Print one population's seconds per chunk, per command of ``log`` and over all of them."""
    total_s = total_n = 0.0
    for start, lines in commands(log, trials, name):
        (end, mean), (first, first_mean) = lines[-1], lines[0]
        elapsed = mean * (end - start)
        rest_s, rest_n = elapsed - first_mean * (first - start), end - first
        print(f"{label}: chunks {start + 1}-{end} in {elapsed:.1f} s, chunks {first + 1}-{end}: "
              f"{rest_s / rest_n:.2f} s each")
        total_s, total_n = total_s + rest_s, total_n + rest_n
    print(f"{label}: {total_s / total_n:.2f} s a chunk over {int(total_n)} chunks (each command's first printed "
          f"group left out)")


if __name__ == "__main__":
    main(sys.argv[1:] or ["blind", "perceptive"])
