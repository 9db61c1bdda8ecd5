"""``evolve --generator mixed`` and ``shares`` at smoke size on the CPU (issue 64, item 3): the mixed archive is
written with each elite's generator and its shares per distance band; ``shares`` sets it beside the combined archive
of separate runs; bad flags fail in one line before any run folder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def test_evolve_mixed_smoke_writes_the_archive_and_its_shares(tmp_path):
    from jaxterrain import qd as A

    out = tmp_path / "mixed"
    assert cli("evolve", "--preset", "smoke", "--generator", "mixed", "--mix", "perlin", "worley", "--generations", "2",
               "--batch-size", "6", "--initial-population", "8", "--out", str(out)) == 0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["generator"] == "mixed" and cfg["mix"] == ["perlin", "worley"] and cfg["fresh"] == 1
    arch = A.load(out / "archive.npz")
    assert arch.generator_names == ("perlin", "worley")
    assert set(np.unique(arch.source[arch.filled])) <= {0, 1} and arch.filled.any()
    # the stored heightmap of every elite is its own generator's render of its genome
    from jaxterrain import generators

    for cell in np.flatnonzero(arch.filled)[:2]:
        name, genome = A.elite(arch, cell)
        np.testing.assert_allclose(A.heightmaps(arch)[cell], generators.get(name, size=32).render_one(genome),
                                   atol=2e-5)
    rows = (out / "shares.csv").read_text().splitlines()
    assert rows[0].startswith("archive,band_lo,band_hi,cells,filled,coverage_percent,generator,count,share")
    assert (out / "shares.png").stat().st_size > 0 and "| mixed |" in (out / "shares.md").read_text()
    # shares: the mixed archive beside the combined archive of (here: the mixed one's and a copy's) separate runs
    shares = tmp_path / "shares"
    assert cli("shares", "--mixed", str(out), "--separate", str(out / "archive.npz"), "--out", str(shares)) == 0
    text = (shares / "shares.md").read_text()
    assert "| mixed |" in text and "| combined |" in text
    n = int(arch.filled.sum())  # the combined archive of the mixed one alone is the mixed one, cell by cell
    assert f"Cells filled in both: {n}, held by the same generator in both: {n} (100%)" in text
    assert cli("evolve", "--resume", str(out)) == 0  # done: the saved archive is reused


@pytest.mark.parametrize("args, message", [
    (["evolve", "--generator", "mixed", "--mix", "perlin"], "--mix: two or more distinct generator names"),
    (["evolve", "--generator", "mixed", "--mix", "perlin", "nope"], "--mix: unknown generator 'nope'"),
    (["evolve", "--generator", "perlin", "--fresh", "2"], "--fresh: only with --generator mixed"),
    (["evolve", "--mix", "perlin", "worley"], "--mix: only with --generator mixed"),
    (["evolve", "--generator", "mixed", "--batch-size", "6"], "--batch-size must be > 6 with --generator mixed"),
    (["evolve", "--generator", "mixed", "--fresh", "-1"], "--fresh must be an integer >= 0"),
    (["evolve", "--generator", "mixed", "--size", "48"], "--size 48 does not suit generator 'diamond_square'"),
    (["shares", "--mixed", "NOPE.npz"], "--mixed NOPE.npz: no archive there"),
    (["shares"], "--mixed or --separate"),
])
def test_bad_mixed_flags_fail_before_the_run_folder(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        cli(*args)
    err = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "runs").exists()


def test_shares_refuses_archives_of_other_grids(tmp_path, monkeypatch, capsys):
    from jaxterrain import qd as A

    monkeypatch.chdir(tmp_path)
    a = A.load(ROOT / "docs/results/exp2_perlin_headings_archive.npz")  # roughness x TPI, 50 x 50
    cfg = A.resolve_config(a.config._replace(bins=2))
    small = A.Archive((np.zeros((4, 1), np.float32),), ("perlin",), np.array([0, -1, -1, -1], np.int32),
                      np.array([0.5, -np.inf, -np.inf, -np.inf], np.float32), np.zeros((4, 2), np.float32),
                      np.asarray(A.centroids_for(cfg)), None, cfg, {})
    A.save(tmp_path / "small.npz", small)
    with pytest.raises(SystemExit) as exit_:
        cli("shares", "--mixed", str(tmp_path / "small.npz"), "--separate",
            str(ROOT / "docs/results/exp2_perlin_headings_archive.npz"))
    assert exit_.value.code == 2 and "must share one grid" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


@pytest.mark.slow  # ~50 s of CPU (six generators compile); the two-generator run above covers the command by default
def test_evolve_mixed_smoke_of_all_six_generators(tmp_path):
    from jaxterrain import qd as A

    out = tmp_path / "six"
    assert cli("evolve", "--preset", "smoke", "--generator", "mixed", "--generations", "2", "--batch-size", "12",
               "--initial-population", "24", "--out", str(out)) == 0
    arch = A.load(out / "archive.npz")
    assert arch.generator_names == ("perlin", "worley", "diamond_square", "cppn", "gan", "steps")
    assert arch.filled.any() and arch.source[arch.filled].max() < 6
    assert A.check_cells(arch, generator_options={"size": 32}).all()  # each elite re-derives its cell by its generator
