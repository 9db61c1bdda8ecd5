"""What a newcomer reads: the README is short and its Python runs as written; the docs site's command-line reference
comes from the parsers (``mkdocs build --strict`` itself runs in ``.ci/run``)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import yaml
from scripts import load_script

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
    hook = load_script(ROOT / "docs" / "hooks" / "cli.py", "cli_hook")
    from experiments.__main__ import COMMANDS

    page = hook.on_page_markdown("# Command line\n\n<!-- cli-reference -->\n", None, None, None)
    for name in COMMANDS:
        assert f"## {name}\n" in page and f"usage: python -m experiments {name}" in page
    assert "--baseline" in page and "--reps" in page


def _cli_page() -> str:
    hook = load_script(ROOT / "docs" / "hooks" / "cli.py", "cli_hook")
    return hook, hook.on_page_markdown((ROOT / "docs" / "cli.md").read_text(), None, None, None)


def test_the_command_line_page_is_generated_from_the_parsers_and_agrees_with_help():
    """docs/cli.md as the site builds it: every marker replaced, every command's --help and --preset help in it
    verbatim, no hidden (deprecated) spelling and no ==SUPPRESS==, and the hand-written stale copies gone."""
    import argparse
    import os

    hook, page = _cli_page()
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    assert "docs/hooks/cli.py" in config["hooks"]
    assert not any(m in page for m in hook.MARKERS)
    os.environ["COLUMNS"] = "110"
    from experiments.__main__ import build_parser

    _, commands = build_parser()
    for name, (_, parser) in commands.items():
        assert parser.format_help().rstrip() in page, name
        preset = next((a for a in parser._actions if a.dest == "preset"), None)
        row = next(line for line in page.splitlines() if line.startswith(f"| `{name}` |"))
        if preset is not None:
            assert " ".join(preset.help.split()).replace("|", "\\|") in row, name
            for choice in preset.choices:
                assert f"{choice}: " in row or "same settings" in row, (name, choice)
        section = page.split(f"\n## {name}\n")[1].split("\n## ")[0]
        for action in parser._actions:
            if action.help == argparse.SUPPRESS:
                for option in action.option_strings:
                    assert not re.search(re.escape(option) + r"(?![-\w])", section), (name, option)
    for stale in ("==SUPPRESS==", "map\\|roughness", "about a minute", "`evolve` and `coverage` also have"):
        assert stale not in page, stale
    assert "| `default` |" not in page.split("<!--")[0]  # gradient's presets: in its own row, not as a preset
    for preset in ("smoke", "gpu-short", "gpu", "paper"):
        assert f"| `{preset}` |" in page


def test_test_counts_live_in_the_readme_only():
    """The README's test line is the one place with the suite's count and time; no docs page repeats a copy."""
    readme = (ROOT / "README.md").read_text()
    assert re.search(r"\d+ passed, \d+ skipped in \d+ min", readme)
    for page in (ROOT / "docs").rglob("*.md"):
        if "results" not in page.parts:
            assert not re.search(r"\d+ passed, \d+ skipped", page.read_text()), page
