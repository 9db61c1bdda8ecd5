"""``docs/results/sim2sim/measure.py``'s summary pairs the engines of one (walker, terrain) whatever run wrote them:
a resumed run reads its earlier rows back from ``fitness.csv`` (strings) beside its own (ints)."""

from scripts import load_script


def test_a_resumed_runs_rows_pair_with_the_earlier_runs():
    measure = load_script("docs/results/sim2sim/measure.py", "sim2sim_measure")
    base = dict(group="humanoid base", policy="base_humanoid", robot="humanoid", family="perlin", mean_steps="80.0")
    earlier = [dict(base, level="0", terrain="0", engine="mjx", fitness="0.500000"),  # as read back from the csv
               dict(base, level="0", terrain="0", engine="mujoco", fitness="0.400000")]
    now = [dict(base, level=0, terrain=0, engine="warp", fitness="0.450000")]  # as this run records them
    summary, text = measure.summarise(earlier + now, {"attempts": 20, "best": 5, "terrains": 1})
    cell = summary["pairs"]["warp-mjx"]["humanoid base|all"]
    assert cell["n"] == 1 and abs(cell["mean"] + 0.05) < 1e-9
    assert abs(summary["pairs"]["mujoco-warp"]["all|all"]["mean"] + 0.05) < 1e-9
    assert "## warp - mjx" in text


def test_the_engine_comparison_pairs_walks_and_resamples_maps():
    """``engines.py``: |C - Warp| - |C - MJX| per walk, averaged; a constant difference has a point interval."""
    engines = load_script("docs/results/sim2sim/engines.py", "sim2sim_engines")
    t = {("g", "p", m): {"mujoco": 0.5, "warp": 0.45, "mjx": 0.3 + 0.01 * (m % 2)} for m in range(6)}
    r = engines.compare(t, "g", samples=50)
    assert r["pairs"] == 6 and r["maps"] == 6
    assert abs(r["c_warp"] - 0.05) < 1e-9 and abs(r["c_mjx"] - 0.195) < 1e-9
    assert r["diff_ci95"][0] <= r["diff"] <= r["diff_ci95"][1] and r["diff_ci95"][1] < 0
