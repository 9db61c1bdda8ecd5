"""``docs/results/suite_v2/spawn_check.py``: the ant's old spawn rule starts feet inside rising terrain of suite v2,
the default rule none (slow: a small suite build and two compiles of the ant's reset)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "suite_v2" / "spawn_check.py"


@pytest.mark.slow
def test_the_old_spawn_cuts_the_ants_feet_into_rising_ground_and_the_default_does_not(tmp_path, capsys):
    script = load_script(SCRIPT, "suite_v2_spawn_check")
    assert script.main(["--out", str(tmp_path), "--robots", "ant", "--size", "96", "--keys", "1"]) == 0
    rows = list(csv.DictReader((tmp_path / "spawn_ant.csv").open()))
    depth = {s: [float(r["depth_m"]) for r in rows if r["spawn"] == s] for s in ("patch", "feet")}
    assert len(depth["patch"]) == len(depth["feet"]) > 100
    assert sum(d > 0.01 for d in depth["patch"]) > 50  # feet cut in more than 1 cm under the old rule
    assert max(depth["feet"]) == pytest.approx(-0.01, abs=2e-3)  # every foot clear by the spawn clearance, or more
    assert "| all |" in (tmp_path / "summary.md").read_text()
    with pytest.raises(SystemExit):
        script.main(["--keys", "0"])
    assert "--keys must be an integer >= 1" in capsys.readouterr().err
