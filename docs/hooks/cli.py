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
    import importlib
    import os

    os.environ["COLUMNS"] = "110"  # argparse wraps help to the terminal: one width wherever the site is built
    from experiments.__main__ import COMMANDS, HelpFormatter
    from experiments.common import show_preset_values

    parts = []
    for name, (module_name, text) in COMMANDS.items():
        parser = argparse.ArgumentParser(prog=f"python -m experiments {name}", description=text,
                                         formatter_class=HelpFormatter)
        module = importlib.import_module(module_name)
        module.add_arguments(parser)
        if hasattr(module, "PRESETS"):
            show_preset_values(parser, module.PRESETS)
        parts.append(f"## {name}\n\n{text}\n\n```text\n{_help(parser).rstrip()}\n```\n")
    return "\n".join(parts)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return markdown.replace(MARKER, cli_reference()) if MARKER in markdown else markdown
