"""mkdocs hook: the command-line page (docs/cli.md) written from the parsers themselves, so it cannot go stale.

Markers in a page, each replaced when the site is built:

- ``<!-- cli-presets -->``: the presets every long command takes, each with its meaning
  (``experiments.common.PRESET_HELP``);
- ``<!-- cli-commands -->``: every command of ``python -m experiments``, what it does and the presets it takes (its
  ``--preset`` help: also a command's own presets, and how long ``smoke`` takes where measured);
- ``<!-- cli-reference -->``: every command's ``--help``.

``tests/integration/test_docs.py`` builds the page from this hook and checks it against the parsers."""

from __future__ import annotations

import argparse
import io
import os
from contextlib import redirect_stdout

MARKERS = ("<!-- cli-presets -->", "<!-- cli-commands -->", "<!-- cli-reference -->")
MARKER = MARKERS[-1]


def _help(parser: argparse.ArgumentParser) -> str:
    buf = io.StringIO()
    with redirect_stdout(buf):
        parser.print_help()
    return buf.getvalue()


def _commands():
    os.environ["COLUMNS"] = "110"  # argparse wraps help to the terminal: one width wherever the site is built
    from experiments.__main__ import COMMANDS, build_parser

    _, commands = build_parser()
    return COMMANDS, commands


def cli_presets() -> str:
    from experiments.common import PRESET_HELP, PRESET_NAMES

    smoke = "minutes on 2 CPU cores (each command's `--help` says how many, where measured)"
    rows = [f"| `{name}` | {PRESET_HELP[name].format(smoke=smoke)} |" for name in PRESET_NAMES]
    return "\n".join(["| preset | meaning |", "| --- | --- |", *rows])


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def cli_commands() -> str:
    described, commands = _commands()
    rows = []
    for name, (_, parser) in commands.items():
        preset = next((a for a in parser._actions if a.dest == "preset"), None)
        presets = "-" if preset is None else _cell(preset.help)
        rows.append(f"| `{name}` | {_cell(described[name][1])} | {presets} |")
    return "\n".join(["| command | what it does | presets |", "| --- | --- | --- |", *rows])


def cli_reference() -> str:
    described, commands = _commands()
    return "\n".join(f"## {name}\n\n{described[name][1]}\n\n```text\n{_help(command).rstrip()}\n```\n"
                     for name, (_, command) in commands.items())


def on_page_markdown(markdown: str, page, config, files) -> str:
    for marker, make in zip(MARKERS, (cli_presets, cli_commands, cli_reference)):
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown
