"""The README's main command, at a small size: it must write real figures and tables."""

import csv

import numpy as np
import pytest

from experiments.__main__ import main


def test_quickstart_writes_figures_and_tables(tmp_path):
    out = tmp_path / "run"
    assert main(["quickstart", "--terrains", "4", "--size", "64", "--out", str(out), "--walk", "2", "--attempts", "2",
                 "--best", "1", "--generators", "perlin", "diamond_square", "worley", "--report-frames", "0"]) == 0
    for name in ("terrains.png", "descriptors.png", "difficulty.png", "descriptors.csv", "summary.md", "config.json"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "terrains.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = list(csv.DictReader((out / "descriptors.csv").open()))
    assert [r["generator"] for r in rows] == ["perlin"] * 4 + ["diamond_square"] * 4 + ["worley"] * 4
    tri = np.array([float(r["tri"]) for r in rows])
    rough = np.array([float(r["roughness"]) for r in rows])
    # descriptors of real terrains: positive, and roughness (max - min) bounds TRI (mean |difference|)
    assert np.all(tri > 0) and np.all(rough >= tri) and np.all(rough <= 1)
    summary = (out / "summary.md").read_text()
    assert "| perlin |" in summary and "| worley |" in summary
    # the first 2 terrains of each generator were walked by the base policy: fitness in [0, 1], the rest empty
    fitness = [r["fitness"] for r in rows]
    assert all(f == "" for i, f in enumerate(fitness) if i % 4 >= 2)
    walked = np.array([float(f) for i, f in enumerate(fitness) if i % 4 < 2])
    assert walked.shape == (6,) and np.all((walked >= 0) & (walked <= 1))
    assert "Fitness: the shipped base policy" in summary and "difficulty.png" in summary
    # it ends by writing its report: every figure embedded, the tables in it (videos are tested in test_report)
    import base64

    page = (out / "report" / "report.html").read_text()
    for name in ("terrains.png", "descriptors.png", "difficulty.png"):
        assert base64.b64encode((out / name).read_bytes()).decode() in page, name
    assert ">descriptors.csv<" in page and ">summary.md<" in page and "Videos not requested" in page
    assert (out / "report" / "report.md").is_file()


def test_quickstart_rejects_bad_walk_options(tmp_path, capsys):
    for bad in (["--walk", "-1"], ["--attempts", "0"], ["--attempts", "2", "--best", "3"], ["--report-frames", "-1"]):
        with pytest.raises(SystemExit) as err:  # a usage error: one line naming the flag, exit status 2
            main(["quickstart", "--out", str(tmp_path / "never"), *bad])
        message = str(err.value) + capsys.readouterr().err
        assert err.value.code == 2 or "--" in str(err.value), bad
        assert any(flag in message for flag in ("--walk", "--attempts", "--best", "--report-frames")), message
    assert not (tmp_path / "never").exists()
