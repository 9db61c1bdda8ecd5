"""How much Experiment 4's perceptive walkers use their height scan: per treatment, the mean over its walkers of
the first policy layer's absolute weights on the 153 scan values, the blind inputs' absolute weights and how far
training moved them from the perceptive base policy, and the scan normaliser's median standard deviation and
sample count. CPU, seconds; run from the repository root after unpacking the walkers:

    tar xzf docs/results/exp4/archives/humanoid-perceptive.tar.gz
    python docs/results/exp4/scan_weights.py [runs/exp4/train/humanoid-perceptive]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from jaxterrain import rl
from jaxterrain.rl.networks import stats_std

BASE = Path(__file__).resolve().parents[3] / "jaxterrain" / "assets" / "base_policy_perceptive"


def first_layer(policy) -> np.ndarray:
    """[O, H] the policy network's first dense kernel."""
    return np.asarray(policy.params["policy"]["params"]["mlp"]["hidden_0"]["kernel"])


def main(run: Path) -> None:
    base = rl.load_policy(BASE)
    blind = int(base.meta["observation_size"]) - len(base.meta["surgery"]["scan_mean"])  # 198 - 153 = 45
    w0 = first_layer(base)
    print(f"base: {float(base.normaliser.count):.3g} samples, scan std "
          f"{np.median(np.asarray(stats_std(base.normaliser))[blind:]):.3f} m (median)")
    for treatment in sorted(p for p in run.iterdir() if (p / "policies").is_dir()):
        rows = []
        for trial in sorted((treatment / "policies").glob("trial_*")):
            p = rl.load_policy(trial)
            w, std = first_layer(p), np.asarray(stats_std(p.normaliser))
            rows.append((float(p.normaliser.count), np.median(std[blind:]), np.abs(w[blind:]).mean(),
                         np.abs(w[:blind]).mean(), np.abs(w[:blind] - w0[:blind]).mean()))
        r = np.mean(rows, axis=0)
        print(f"{treatment.name}: {len(rows)} walkers, {r[0]:.3g} samples, scan std {r[1]:.3f} m (median), "
              f"|w| scan {r[2]:.4f}, blind {r[3]:.4f} (moved {r[4]:.4f})")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "runs/exp4/train/humanoid-perceptive"))
