"""What a newcomer reads: the README is short and its Python runs as written; the docs site's command-line reference
comes from the parsers (``mkdocs build --strict`` itself runs in ``.ci/run``)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def test_readme_is_short_and_its_python_runs_as_written(tmp_path):
    text = (ROOT / "README.md").read_text()
    assert len(text.split()) <= 1200
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks, "the README shows how to plug in a generator"
    script = tmp_path / "readme.py"
    script.write_text("\n".join(blocks))
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "(8, 2)" in done.stdout


def test_every_page_of_the_site_exists_and_every_readme_link_resolves():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())

    def pages(nav):
        for item in nav:
            for value in item.values():
                yield from pages(value) if isinstance(value, list) else [value]

    for page in pages(config["nav"]):
        assert (ROOT / "docs" / page).is_file(), page
    for link in re.findall(r"\]\(([^)#]+)\)", (ROOT / "README.md").read_text()):
        if "://" not in link:
            assert (ROOT / link).exists(), link


def test_the_cli_reference_has_every_commands_help():
    spec = importlib.util.spec_from_file_location("cli_hook", ROOT / "docs" / "hooks" / "cli.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    from experiments.__main__ import COMMANDS

    page = hook.on_page_markdown("# Command line\n\n<!-- cli-reference -->\n", None, None, None)
    for name in COMMANDS:
        assert f"## {name}\n" in page and f"usage: python -m experiments {name}" in page
    assert "--baseline" in page and "--reps" in page
