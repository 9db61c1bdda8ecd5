"""``python -m experiments generalise``: Experiment 3's aggregation of held-out evaluations, on hand-made ones (no
walking: the evaluations are CSVs as ``evaluate`` writes them). A treatment whose walkers score higher on every cell
gets the higher interquartile mean, beats the base policy with probability 1, and the rank correlation of the
paper's metric with the held-out scores is the one the numbers imply."""

from __future__ import annotations

import csv
import gzip
import io
import json

import numpy as np
import pytest

from jaxterrain import suite

FAMILIES = [("flat", 1), ("gaps", 3), ("gen:perlin", 2)]  # (family, levels); two seeds per level


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def write_treatment(folder, walker_scores, base_scores, hardest, gz=False):
    """``folder/summary.json`` and ``folder/heldout/fitness.csv``: trial K's walker scores ``walker_scores[K]`` on
    every terrain, the base policy ``base_scores``."""
    terrains = [(f, lv, s) for f, levels in FAMILIES for lv in range(levels) for s in range(2)]
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["policy", "family", "level", "seed", "value", "unit", "fitness"])
    named = [("base", base_scores)] + [(f"/root/x/{folder.name}/policies/trial_{k}", s)
                                       for k, s in enumerate(walker_scores)]
    for name, score in named:
        for (f, lv, s), v in zip(terrains, np.broadcast_to(score, (len(terrains),))):
            w.writerow([name, f, lv, s, lv, "cm", f"{v:.4f}"])
    (folder / "heldout").mkdir(parents=True)
    if gz:
        (folder / "heldout" / "fitness.csv.gz").write_bytes(gzip.compress(buf.getvalue().encode()))
    else:
        (folder / "heldout" / "fitness.csv").write_text(buf.getvalue())
    (folder / "summary.json").write_text(json.dumps({"hardest": list(hardest), "hardest_mean": float(np.mean(hardest))}))
    return len(terrains)


def test_generalise_ranks_the_better_walkers_first(tmp_path, capsys):
    run = tmp_path / "exp3"  # a trial that went further on its archive also walks better here: rank correlation 1
    n = write_treatment(run / "good-map", np.linspace(0.7, 0.75, 4)[:, None], 0.3, [30, 31, 32, 33])
    write_treatment(run / "poor-random", np.linspace(0.4, 0.45, 4)[:, None], 0.3, [10, 11, 12, 13], gz=True)
    (run / "not-a-treatment").mkdir()
    assert cli("generalise", str(run), "--reps", "30") == 0
    out = run / "generalisation"
    assert "highest IQM: good map" in capsys.readouterr().out
    rows = {(r["treatment"], r["scope"]): r for r in csv.DictReader((out / "intervals.csv").open())}
    assert float(rows[("good map", "all")]["iqm_low"]) > float(rows[("poor random", "all")]["iqm_high"])
    assert rows[("base policy", "all")]["runs"] == "2" and rows[("good map", "gaps")]["tasks"] == "3"
    assert float(rows[("base policy", "all")]["mean"]) == pytest.approx(0.3)
    pi = {(r["x"], r["y"]): float(r["probability"]) for r in csv.DictReader((out / "improvement.csv").open())}
    assert pi[("good map", "base policy")] == 1.0 and pi[("good map", "poor random")] == 1.0
    assert pi[("poor random", "good map")] == 0.0
    corr = json.loads((out / "correlation.json").read_text())
    assert corr["trials"]["n"] == 8 and corr["trials"]["spearman"] == pytest.approx(1.0)
    trials = list(csv.DictReader((out / "trials.csv").open()))
    assert len(trials) == 8 and trials[0]["treatment"] == "good map" and trials[0]["trial"] == "0"
    md = (out / "generalisation.md").read_text()
    assert "| good map | 4 |" in md and "Families no treatment improves on (intervals overlap the base policy's, or lie " \
        "below it): none." in md
    assert "**The base policy is one policy**: its 2 runs are evaluations of the same weights" in md
    assert rows[("base policy", "all")]["note"].startswith("one policy") and rows[("good map", "all")]["note"] == ""
    for fig in ("iqm.png", "families.png", "improvement.png", "hardest_vs_heldout.png"):
        assert (out / fig).stat().st_size > 0
    ev = suite.read_fitness(run / "poor-random" / "heldout" / "fitness.csv.gz")
    assert ev.fitness.shape == (5, n) and ev.policies[0] == "base"
    cells, scores = suite.cell_scores(ev.fitness, ev.family, ev.level)
    assert cells == [("flat", 0), ("gaps", 0), ("gaps", 1), ("gaps", 2), ("gen:perlin", 0), ("gen:perlin", 1)]
    assert scores.shape == (5, 6)


def test_generalise_reports_intervals_over_whole_trials_by_default(tmp_path):
    """Each walker scores the same on every terrain (perfectly correlated cells): the default interval is the
    bootstrap interval of the trial means, computed here directly; rliable's stratified interval (resampling each
    cell on its own) is kept beside it and is narrower. The base policy, evaluated once, has no trial variance."""
    means = np.array([0.52, 0.61, 0.55, 0.70, 0.58])
    write_treatment(tmp_path / "run" / "t-map", means[:, None], np.linspace(0.2, 0.4, 12), [1, 2, 3, 4, 5])
    out = tmp_path / "out"
    assert cli("generalise", str(tmp_path / "run" / "t-map"), "--reps", "500", "--seed", "3", "--out", str(out),
               "--permutations", "50") == 0
    rows = {(r["treatment"], r["scope"]): r for r in csv.DictReader((out / "intervals.csv").open())}
    r = rows[("t map", "all")]
    rows_drawn = np.random.default_rng(3).integers(0, 5, (500, 5))
    lo, hi = np.percentile(means[rows_drawn].mean(axis=1), [2.5, 97.5])
    assert float(r["mean_low"]) == pytest.approx(lo, abs=1e-4) and float(r["mean_high"]) == pytest.approx(hi, abs=1e-4)
    assert float(r["trial_iqm_low"]) == pytest.approx(lo, abs=1e-4)      # each trial's IQM is its mean here
    assert float(r["iqm_low_terrains"]) == pytest.approx(float(r["iqm_low"]), abs=1e-3)  # no terrain variance
    assert float(r["mean_high_stratified"]) - float(r["mean_low_stratified"]) < 0.7 * (hi - lo)
    b = rows[("base policy", "all")]
    assert b["runs"] == "1" and b["iqm_low"] == b["iqm_high"] == b["iqm"] and "no trial variance" in b["note"]
    pi = {(p["x"], p["y"]): p for p in csv.DictReader((out / "improvement.csv").open())}
    assert float(pi[("t map", "base policy")]["probability"]) == 1.0
    md = (out / "generalisation.md").read_text()
    assert "its 1 run is one evaluation of the same weights" in md and "an interval of zero width" in md
    assert f"| t map | 5 | {means.mean():.3f}" not in md                # the IQM column comes first
    assert f"[{lo:.3f}, {hi:.3f}]" in md and "5 of 5 |" in md


def test_generalise_holm_adjusts_pairwise_comparisons(tmp_path):
    """Three treatments: three pairs, Welch's test on the trials' means and its Holm adjustment, as computed here."""
    from scipy import stats

    from jaxterrain.runtime import statistics

    trials = {"a-map": [0.50, 0.52, 0.55, 0.51], "b-map": [0.53, 0.56, 0.54, 0.58], "c-map": [0.70, 0.72, 0.69, 0.74]}
    for name, m in trials.items():
        write_treatment(tmp_path / "run" / name, np.array(m)[:, None], 0.3, [1, 2, 3, 4])
    assert cli("generalise", str(tmp_path / "run"), "--reps", "50", "--permutations", "50") == 0
    rows = {(r["x"], r["y"]): r for r in csv.DictReader((tmp_path / "run" / "generalisation" / "improvement.csv").open())}
    pairs = [("a map", "b map"), ("a map", "c map"), ("b map", "c map")]
    raw = [stats.ttest_ind(trials[a.replace(" ", "-")], trials[b.replace(" ", "-")], equal_var=False).pvalue
           for a, b in pairs]
    for (a, b), p, h in zip(pairs, raw, statistics.holm(raw)):
        for key in ((a, b), (b, a)):
            for col in ("", "_mean"):  # every cell of a trial equal: its IQM is its mean
                assert float(rows[key]["welch_p" + col]) == pytest.approx(p, rel=1e-3)
                assert float(rows[key]["holm_p" + col]) == pytest.approx(h, rel=1e-3)
    assert rows[("a map", "base policy")]["welch_p"] == ""
    corr = json.loads((tmp_path / "run" / "generalisation" / "correlation.json").read_text())
    assert corr["within_stratified"]["groups"] == 3 and corr["within_stratified"]["reps"] == 50


def test_generalise_refuses_folders_without_evaluations(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit):
        cli("generalise", str(tmp_path / "empty"))
    with pytest.raises(SystemExit):
        cli("generalise", str(tmp_path / "missing"))
    with pytest.raises(SystemExit):
        cli("generalise", str(tmp_path / "empty"), "--reps", "0")
    with pytest.raises(SystemExit):
        cli("generalise", str(tmp_path / "empty"), "--permutations", "0")


def test_generalise_refuses_two_treatments_of_one_name_and_takes_treatment_folders(tmp_path, capsys):
    """Two runs that both hold a ``cppn-plr`` (a re-run beside the first) are refused, naming both; passing the
    treatment folders themselves picks one, and ``LABEL=FOLDER`` names them apart."""
    for run in ("first", "rerun"):
        write_treatment(tmp_path / run / "cppn-plr", np.linspace(0.4, 0.45, 2)[:, None], 0.3, [10, 11])
    write_treatment(tmp_path / "first" / "cppn-dr", np.linspace(0.5, 0.55, 2)[:, None], 0.3, [12, 13])
    with pytest.raises(SystemExit):
        cli("generalise", str(tmp_path / "first"), str(tmp_path / "rerun"))
    err = capsys.readouterr().err
    assert "two treatments named 'cppn plr'" in err and "first/cppn-plr" in err and "rerun/cppn-plr" in err
    out = tmp_path / "both"
    assert cli("generalise", str(tmp_path / "first" / "cppn-dr"), str(tmp_path / "rerun" / "cppn-plr"),
               "--reps", "20", "--out", str(out)) == 0
    assert {r["treatment"] for r in csv.DictReader((out / "intervals.csv").open())} == {"cppn dr", "cppn plr",
                                                                                      "base policy"}
    # LABEL=FOLDER names them: a treatment folder LABEL, a run's treatments "LABEL <name>"
    assert cli("generalise", str(tmp_path / "first"), f"sized={tmp_path / 'rerun' / 'cppn-plr'}", "--reps", "20",
               "--out", str(out)) == 0
    assert {r["treatment"] for r in csv.DictReader((out / "intervals.csv").open())} == {
        "cppn dr", "cppn plr", "sized", "base policy"}
    assert cli("generalise", f"a={tmp_path / 'first'}", f"b={tmp_path / 'rerun'}", "--reps", "20",
               "--out", str(out)) == 0
    assert {r["treatment"] for r in csv.DictReader((out / "intervals.csv").open())} == {
        "a cppn dr", "a cppn plr", "b cppn plr", "base policy"}


@pytest.mark.parametrize("damage, message", [
    ("summary", "summary.json: not readable JSON (JSONDecodeError"),
    ("hardest", "summary.json: field 'hardest' must be a list of finite numbers"),
    ("short", "summary.json: field 'hardest' has 2 trials, but "),
    ("nan", "heldout/fitness.csv, line 3: fitness must be a finite number in [0, 1]; got 'nan'"),
    ("text", "heldout/fitness.csv, line 3: level and seed must be integers and fitness a number"),
])
def test_generalise_names_the_damaged_file_and_row_in_one_line(tmp_path, capsys, damage, message):
    """issue 59: a damaged ``summary.json`` or a NaN in ``fitness.csv`` ended in tracebacks naming neither file nor
    row."""
    folder = tmp_path / "run" / "t-map"
    write_treatment(folder, np.linspace(0.7, 0.75, 4)[:, None], 0.3, [30, 31, 32, 33])
    summary, fitness = folder / "summary.json", folder / "heldout" / "fitness.csv"
    if damage == "summary":
        summary.write_text('{"hardest": [1, 2')
    elif damage == "hardest":
        summary.write_text(json.dumps({"hardest": ["far", 2, 3, 4]}))
    elif damage == "short":
        summary.write_text(json.dumps({"hardest": [1, 2]}))
    else:
        lines = fitness.read_text().splitlines()
        lines[2] = lines[2].rsplit(",", 1)[0] + (",nan" if damage == "nan" else ",high")
        fitness.write_text("\n".join(lines) + "\n")
    with pytest.raises(SystemExit) as exit_:
        cli("generalise", str(tmp_path / "run"), "--reps", "10")
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("python -m experiments generalise: error: ") and message in err, err
    assert str(folder) in err
    assert not (tmp_path / "run" / "generalisation").exists()


def write_base(path, runs):
    """An ``evaluate --keys K`` fitness.csv of the base policy alone: rows ``base``, ``base:key1``, ... with the
    scores of ``runs`` [K] (one number each, on every terrain)."""
    terrains = [(f, lv, s) for f, levels in FAMILIES for lv in range(levels) for s in range(2)]
    lines = ["policy,family,level,seed,value,unit,fitness"]
    for k, v in enumerate(runs):
        lines += [f"{'base' if k == 0 else f'base:key{k}'},{f},{lv},{s},{lv},cm,{v:.4f}" for f, lv, s in terrains]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def test_generalise_takes_the_base_policys_k_evaluations_as_k_runs_of_the_comparator(tmp_path, capsys):
    """``--base FILE`` (``evaluate --keys K``): the base policy's runs are those K evaluations, on every page the
    same; the treatments' own base rows (here 0.9, which would beat every walker) are not used, and base:keyK rows
    in a treatment's file are never read as walkers."""
    run = tmp_path / "exp3"
    write_treatment(run / "good-map", np.linspace(0.7, 0.75, 4)[:, None], 0.9, [30, 31, 32, 33])
    text = (run / "good-map" / "heldout" / "fitness.csv").read_text().splitlines()
    extra = [line.replace("base,", "base:key1,", 1) for line in text[1:] if line.startswith("base,")]
    (run / "good-map" / "heldout" / "fitness.csv").write_text("\n".join(text + extra) + "\n")
    write_base(tmp_path / "base" / "fitness.csv", [0.30, 0.32, 0.34, 0.36, 0.38])
    assert cli("generalise", str(run), "--base", str(tmp_path / "base"), "--reps", "40") == 0
    out = run / "generalisation"
    rows = {(r["treatment"], r["scope"]): r for r in csv.DictReader((out / "intervals.csv").open())}
    assert rows[("base policy", "all")]["runs"] == "5" and rows[("good map", "all")]["runs"] == "4"
    assert float(rows[("base policy", "all")]["mean"]) == pytest.approx(0.34)
    low, high = float(rows[("base policy", "all")]["mean_low"]), float(rows[("base policy", "all")]["mean_high"])
    assert 0.30 <= low < 0.34 < high <= 0.38  # the five runs spread: an interval of nonzero width
    pi = {(r["x"], r["y"]): float(r["probability"]) for r in csv.DictReader((out / "improvement.csv").open())}
    assert pi[("good map", "base policy")] == 1.0
    assert f"its 5 runs are evaluations (`{tmp_path / 'base'}`, independent keys) of the same weights" in \
        (out / "generalisation.md").read_text()
    capsys.readouterr()
    write_base(tmp_path / "short.csv", [0.3])
    lines = (tmp_path / "short.csv").read_text().splitlines()
    (tmp_path / "short.csv").write_text("\n".join(lines[:-1]) + "\n")  # a terrain fewer
    with pytest.raises(SystemExit) as stop:
        cli("generalise", str(run), "--base", str(tmp_path / "short.csv"), "--reps", "10")
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert "--base" in err and "other terrains" in err and len(err.strip().splitlines()) == 1


def test_generalise_reads_another_heldout_folder_and_sets_another_aggregate_beside(tmp_path, capsys):
    """``--heldout heldout_v2`` reads each treatment's suite-v2 evaluation (``reevaluate.py``'s folder) instead of
    ``heldout/``; ``--beside v1=DIR`` sets the same treatments' v1 aggregate beside it: both IQMs, the ranks (here
    the order of two treatments flips between the suites), each trial's cell mean on both and the pairs each
    separates."""
    run = tmp_path / "exp3"
    spec = {"a-map": (0.70, 0.40), "b-map": (0.50, 0.60), "c-map": (0.30, 0.20)}   # (v1, v2) trial means' centre
    for name, (v1, v2) in spec.items():
        write_treatment(run / name, (v2 + np.linspace(0, 0.03, 5))[:, None], 0.1, [1, 2, 3, 4, 5])
        (run / name / "heldout").rename(run / name / "heldout_v2")
        write_treatment(run / name, (v1 + np.linspace(0, 0.03, 5))[:, None], 0.1, [1, 2, 3, 4, 5])
    (run / "a-map" / "heldout_v2" / "config.json").write_text(json.dumps({"suite": "v2", "robot": "humanoid"}))
    assert cli("generalise", str(run), "--reps", "40", "--permutations", "20", "--out", str(tmp_path / "v1")) == 0
    rows = {(r["treatment"], r["scope"]): r for r in csv.DictReader((tmp_path / "v1" / "intervals.csv").open())}
    assert float(rows[("a map", "all")]["mean"]) == pytest.approx(0.715, abs=1e-4)
    assert cli("generalise", str(run), "--heldout", "heldout_v2", "--beside", f"v1={tmp_path / 'v1'}", "--reps", "40",
               "--permutations", "20", "--out", str(tmp_path / "v2")) == 0
    out = tmp_path / "v2"
    rows = {(r["treatment"], r["scope"]): r for r in csv.DictReader((out / "intervals.csv").open())}
    assert float(rows[("a map", "all")]["mean"]) == pytest.approx(0.415, abs=1e-4)  # heldout_v2's walkers
    assert json.loads((out / "meta.json").read_text())["suite"] == "v2:humanoid"
    beside = {r["treatment"]: r for r in csv.DictReader((out / "beside.csv").open())}
    assert [beside[n]["rank"] for n in ("a map", "b map", "c map")] == ["2", "1", "3"]
    assert [beside[n]["rank_beside"] for n in ("a map", "b map", "c map")] == ["1", "2", "3"]
    assert float(beside["a map"]["iqm_beside"]) == pytest.approx(float(rows[("a map", "all")]["iqm"]) + 0.3, abs=1e-3)
    md = (out / "generalisation.md").read_text()
    assert "## Beside v1 (`" in md and "| treatment | IQM v2:humanoid | IQM v1 |" in md
    assert "Each trial's cell mean, v2:humanoid against v1 (n = 15 walkers)" in md
    assert "separated on both, the same way: 2; on v2:humanoid only: 0; on v1 only: 0; reversed: 1" in md
    assert "reversed (as v2:humanoid has them): b map > a map" in md
    assert (out / "beside.png").stat().st_size > 0
    capsys.readouterr()
    for argv, text in ((["--heldout", "a/b"], "--heldout must be a folder name"),
                       (["--heldout", "heldout_v3"], "no treatment with heldout_v3/fitness.csv"),
                       (["--beside", str(tmp_path)], "no intervals.csv in it")):
        with pytest.raises(SystemExit) as stop:
            cli("generalise", str(run), "--reps", "10", *argv)
        err = capsys.readouterr().err
        assert stop.value.code == 2 and text in err and len(err.strip().splitlines()) == 1


def test_generalise_reports_the_levels_each_treatment_passes_beyond_the_base_policy(tmp_path):
    run = tmp_path / "exp4"  # walkers at 0.95 everywhere pass every level; the base policy (0.3) fails level 0
    write_treatment(run / "climber", np.full((3, 1), 0.95), 0.3, [1, 2, 3])
    write_treatment(run / "sitter", np.full((3, 1), 0.5), 0.3, [1, 2, 3])
    assert cli("generalise", str(run), "--reps", "30") == 0
    rows = {(r["treatment"], r["family"]): r for r in csv.DictReader((run / "generalisation" / "levels.csv").open())}
    assert float(rows[("climber", "gaps")]["walkers"]) == 2.0 and float(rows[("climber", "gaps")]["base"]) == -1.0
    assert (float(rows[("climber", "gaps")]["gain_low"]), float(rows[("climber", "gaps")]["gain_high"])) == (3.0, 3.0)
    assert float(rows[("sitter", "gaps")]["gain"]) == 0.0
    md = (run / "generalisation" / "generalisation.md").read_text()
    assert "## Levels passed" in md and "| gaps | -1.0 | **+3.0 [+3.0, +3.0]** | +0.0 [+0.0, +0.0] |" in md



def test_generalise_draws_a_treatment_of_one_trial(tmp_path):
    """One trial (Experiment 4's CPU check, ``tests/data/generalise_one_trial``: its smoke walker and the base
    policy's two keys on a 96 px v2 of flat and boxes, as ``exp4/run.py`` wrote them): an interval over one trial has
    its ends at the point up to float rounding, which matplotlib's error bars refused as negative lengths."""
    from pathlib import Path

    data = Path(__file__).resolve().parents[1] / "data" / "generalise_one_trial"
    assert cli("generalise", f"mixed-map={data / 'mixed-map'}", "--heldout", "heldout_v2", "--base",
               str(data / "base"), "--reps", "30", "--out", str(tmp_path / "g")) == 0
    assert (tmp_path / "g" / "iqm.png").stat().st_size > 0 and (tmp_path / "g" / "families.png").stat().st_size > 0
