"""Seconds per chunk of Experiment 4's humanoid training, read back from the device logs (logs/blind_gpu0.log.gz:
GPU 0, `train humanoid blind --shard 0/2`: the mixed and steps map treatments as one 20-trial population, then
terrain levels alone, 10 trials; logs/blind_gpu1.log.gz: GPU 1, `--shard 1/2`: DR and PLR as one 20-trial
population). 2 x H200, MuJoCo Warp with the heightfield patch, 2026-11-30.

    python docs/results/exp4/chunk_times.py

A population prints ``population K: chunk C of 75, ... (mean of T trials, ...), S s/chunk``, S the command's running
mean over the chunks it has done (rounded to 0.1 s). The lines are told apart by their trial count T (20: a pair of
treatments, 10: one alone). Per command this leaves out the first printed group of chunks (a cold first chunk holds
Warp's kernel compiles: 72-90 s; a resumed one's first group 8-13 s more than the rest) and prints the mean of the
rest; then the mean over the commands, weighted by chunks. Commands are split as in
``docs/results/population/chunk_times.py``.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("chunk_times", HERE.parent / "population" / "chunk_times.py")
population_times = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(population_times)

LINE = r"population \d+: chunk (\d+) of \d+, hardest [\d.]+ cells \(mean of {trials} trials.*?([\d.]+) s/chunk"
RUNS = {"GPU 0: mixed map + steps map (20 trials)": ("blind_gpu0.log.gz", 20),
        "GPU 0: mixed levels alone (10 trials)": ("blind_gpu0.log.gz", 10),
        "GPU 1: mixed DR + mixed PLR (20 trials)": ("blind_gpu1.log.gz", 20)}


def per_command(lines: list[tuple[int, float]], start: int) -> tuple[int, float, float, int]:
    """``(last chunk, elapsed s, s of the chunks after the first printed group, their count)`` of one command whose
    previous command ended at chunk ``start``."""
    end, mean = lines[-1]
    first, first_mean = lines[0]
    elapsed = mean * (end - start)
    return end, elapsed, elapsed - first_mean * (first - start), end - first


def main() -> None:
    for name, (log, trials) in RUNS.items():
        total_s = total_n = 0.0
        start = 0
        for lines in population_times.commands(HERE / "logs" / log, LINE.format(trials=trials)):
            if lines[0][0] <= start:  # a new treatment's population restarts its count
                start = 0
            end, elapsed, rest_s, rest_n = per_command(lines, start)
            print(f"{name}: chunks {start + 1}-{end} in {elapsed:.1f} s, chunks {lines[0][0] + 1}-{end}: "
                  f"{rest_s / rest_n:.2f} s each")
            total_s, total_n, start = total_s + rest_s, total_n + rest_n, end
        print(f"{name}: {total_s / total_n:.2f} s a chunk over {int(total_n)} chunks (each command's first printed "
              f"group left out)")


if __name__ == "__main__":
    main()
