"""``docs/results/exp4/run.py`` end to end at the tiniest size on the CPU (slow: several programs compile): the
mixed archive, the humanoid's blind and perceptive runs (one treatment each, ``--treatments mixed-map``), the ant's
``steps`` archive and one ant treatment, the evaluation of every walker and base policy on suite v2 and v1 (a tiny
build: ``flat`` and ``boxes`` at 96 px, 2 walks), ``--pack``, ``--plan`` and ``write`` (generalise's levels passed
per robot, observation set and suite). Each stage run again says ``done`` without running anything. The stages that
run on the GPU machine run as there, without the packages its image lacks (``tests/gpu_image.py``); ``write`` runs
where the results are read."""

from __future__ import annotations

import tarfile
from pathlib import Path

import pytest
from gpu_image import image
from scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "docs" / "results" / "exp4" / "run.py"
TINY = ["--size", "96", "--seeds", "1", "--families", "flat", "boxes", "--generators", "--attempts", "2", "--best",
        "1", "--headings", "1", "--slots", "0"]


def load():
    module = load_script(SCRIPT, "exp4_run_e2e")
    return module


@pytest.mark.slow
def test_every_stage_runs_at_the_tiniest_size(tmp_path, monkeypatch, capsys, request):
    monkeypatch.chdir(tmp_path)
    gpu = pytest.MonkeyPatch()  # the GPU image, until write
    request.addfinalizer(gpu.undo)
    image(gpu)
    run = load()
    out = tmp_path / "exp4"
    base = ["--out", str(out), "--preset", "smoke", "--trials", "1", "--keys", "2"]

    def stage(*argv):
        code = run.main([*argv, *base])
        return code, capsys.readouterr().out

    assert stage("archive", "mixed", "--archive-size", "64")[0] == 0
    assert (out / "archive" / "humanoid-mixed" / "archive.npz").is_file()
    code, text = stage("archive", "mixed", "--archive-size", "64")
    assert code == 0 and "archive humanoid mixed: done" in text and "+ python" not in text  # nothing runs again
    assert stage("train", "humanoid", "blind", "--treatments", "mixed-map")[0] == 0
    assert stage("train", "humanoid", "perceptive")[0] == 0  # the choice saved in humanoid.json
    for obs in ("blind", "perceptive"):
        folder = out / "train" / f"humanoid-{obs}"
        assert sorted(p.name for p in folder.iterdir() if p.is_dir()) == ["mixed-map"]
        assert (folder / "mixed-map" / "policies" / "trial_0" / "policy.msgpack").is_file()
    code, text = stage("train", "humanoid", "blind")
    assert code == 0 and "train humanoid blind: done" in text and "+ python" not in text
    assert stage("train", "ant", "--ant", "blind/steps-map")[0] == 2  # its archive first, said in one line
    assert stage("archive", "steps", "--robot", "ant", "--archive-size", "80")[0] == 0
    assert stage("train", "ant", "--ant", "blind/steps-map")[0] == 0
    assert (out / "train" / "ant-blind" / "steps-map" / "summary.json").is_file()

    # two parts into one store (exp4_eval.sh's one process per GPU), one after the other here
    code, text = stage("evaluate", *TINY, "--eval-backend", "jax", "--part", "0/2")
    assert code == 0 and "evaluate part 0/2: done" in text, text
    code, text = stage("evaluate", *TINY, "--eval-backend", "jax", "--part", "1/2", "--pack",
                       str(tmp_path / "exp4.tar.gz"))
    assert code == 0 and "evaluate part 1/2: done" in text, text
    from jaxterrain.suite import batch

    for suite in ("v2", "v1"):  # 3 walkers, 2 robots x 2 observation sets x 2 keys of base policies
        store = batch.Store(out / "eval" / suite)
        names = [m["name"] for m in store.metas()]
        assert len(names) == 3 + 8 and "base:ant:perceptive:key1" in names, names
    with tarfile.open(tmp_path / "exp4.tar.gz") as tar:
        members = tar.getnames()
    assert any(m.endswith("eval/v2/settings.json") for m in members)
    assert not any(m.endswith("checkpoint.npz") for m in members)  # every treatment finished
    assert any(m.endswith("humanoid-perceptive/mixed-map/policies/trial_0/policy.msgpack") for m in members)
    assert run.main(["--plan", *base, *TINY]) == 0
    plan = capsys.readouterr().out
    assert "evaluate v2: humanoid blind 0 walks left, humanoid perceptive 0 walks left, ant blind 0 walks left, " \
           "ant perceptive 0 walks left (rates recorded in" in plan

    gpu.undo()
    results = tmp_path / "results"
    assert stage("write", *TINY, "--results", str(results))[0] == 0
    for name in ("humanoid-blind", "humanoid-perceptive", "ant-blind"):
        for suite in ("v2", "v1"):
            levels = (results / name / suite / "levels.csv").read_text().splitlines()
            assert levels[0].startswith("treatment,family,") and any(r.startswith("mixed-map,boxes,") or
                                                                     r.startswith("steps-map,boxes,")
                                                                     for r in levels[1:]), (name, suite)
        assert "v1" in (results / name / "v2" / "generalisation.md").read_text()  # v1 beside v2
    assert (out / "base_v2" / "humanoid_perceptive" / "fitness.csv.gz").is_file()
