"""mkdocs hook: the command-line reference (docs/cli.md) from the parsers themselves, so it cannot go stale.

``<!-- cli-reference -->`` in a page is replaced by every command of ``python -m experiments`` with its ``--help``."""

from __future__ import annotations

import argparse
import io
from contextlib import redirect_stdout

MARKER = "<!-- cli-reference -->"


def _help(parser: argparse.ArgumentParser) -> str:
    buf = io.StringIO()
    with redirect_stdout(buf):
        parser.print_help()
    return buf.getvalue()


def cli_reference() -> str:
    import os

    os.environ["COLUMNS"] = "110"  # argparse wraps help to the terminal: one width wherever the site is built
    from experiments.__main__ import COMMANDS, build_parser

    _, commands = build_parser()
    return "\n".join(f"## {name}\n\n{COMMANDS[name][1]}\n\n```text\n{_help(command).rstrip()}\n```\n"
                     for name, (_, command) in commands.items())


def on_page_markdown(markdown: str, page, config, files) -> str:
    return markdown.replace(MARKER, cli_reference()) if MARKER in markdown else markdown
