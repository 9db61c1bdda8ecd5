"""Tables and Markdown for a report page: CSV / TSV tables as HTML or Markdown tables, a small Markdown to HTML
renderer (never linking out), and images embedded as data URIs. Used by :mod:`jaxterrain.report.page`."""

from __future__ import annotations

import base64
import csv
import html
import io
import re
from pathlib import Path
from typing import Callable, Optional, Sequence

__all__ = ["markdown_to_html", "read_table", "MAX_ROWS", "MIME", "escape", "data_uri", "html_table", "md_table", "demote_markdown",
           "image_resolver"]

MAX_ROWS = 500
"""Rows of a table shown on the page; longer tables are cut there (the note names the file)."""

MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".gif": "image/gif",
         ".svg": "image/svg+xml", ".webp": "image/webp"}
escape = html.escape


def data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def read_table(path: Path) -> list[list[str]]:
    """Rows of a CSV / TSV file (header first); ragged rows are kept as they are."""
    text = path.read_text(encoding="utf-8", errors="replace")
    return [row for row in csv.reader(io.StringIO(text), delimiter="\t" if path.suffix.lower() == ".tsv" else ",")]


def html_table(rows: Sequence[Sequence[str]], max_rows: int = MAX_ROWS, header: bool = True) -> str:
    if not rows:
        return "<p class=note>(empty table)</p>"
    width = max(len(r) for r in rows)
    head, body = (rows[0], rows[1:]) if header else ([], rows)
    out = ["<div class=tablebox><table>"]
    if head:
        out.append("<thead><tr>" + "".join(f"<th>{escape(c)}</th>" for c in head) + "</tr></thead>")
    out.append("<tbody>")
    for r in body[:max_rows]:
        cells = list(r) + [""] * (width - len(r))
        out.append("<tr>" + "".join(f"<td{' class=num' if _is_num(c) else ''}>{escape(c)}</td>" for c in cells)
                   + "</tr>")
    out.append("</tbody></table></div>")
    if len(body) > max_rows:
        out.append(f"<p class=note>first {max_rows} of {len(body)} rows shown</p>")
    return "".join(out)


def _is_num(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _md_cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def md_table(rows: Sequence[Sequence[str]], max_rows: int = MAX_ROWS) -> str:
    if not rows:
        return "(empty table)\n"
    width = max(len(r) for r in rows)
    pad = lambda r: list(r) + [""] * (width - len(r))  # noqa: E731
    lines = ["| " + " | ".join(_md_cell(c) for c in pad(rows[0])) + " |", "|" + "---|" * width]
    lines += ["| " + " | ".join(_md_cell(c) for c in pad(r)) + " |" for r in rows[1:max_rows + 1]]
    if len(rows) - 1 > max_rows:
        lines.append(f"\n(first {max_rows} of {len(rows) - 1} rows shown)")
    return "\n".join(lines) + "\n"


def _inline_md(text: str, images: Optional[Callable[[str], Optional[str]]] = None) -> str:
    """Escape, then `code`, **bold**, *italic*, images (embedded when ``images`` resolves them) and links (their
    text only: the page never links out)."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for part in parts:
        if len(part) >= 2 and part.startswith("`") and part.endswith("`"):
            out.append(f"<code>{escape(part[1:-1])}</code>")
            continue

        def image(m):
            src = images(m.group(2)) if images else None
            return f'<img alt="{escape(m.group(1))}" src="{src}">' if src else escape(f"[image: {m.group(1) or m.group(2)}]")

        tokens = []

        def keep(m):
            tokens.append(image(m))
            return f"\x00{len(tokens) - 1}\x00"

        s = re.sub(r"!\[([^\]]*)\]\(([^)\s]+)[^)]*\)", keep, part)
        s = re.sub(r"\[([^\]]+)\]\([^)]*\)", r"\1", s)  # links: text only
        s = escape(s)
        s = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)
        s = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", s)
        s = re.sub(r"https?://", "", s)  # no network address, even as text
        s = re.sub("\x00(\\d+)\x00", lambda m: tokens[int(m.group(1))], s)
        out.append(s)
    return "".join(out)


def markdown_to_html(text: str, demote: int = 2, images: Optional[Callable[[str], Optional[str]]] = None) -> str:
    """A small Markdown renderer for the tables and summaries that commands write: headings (demoted by
    ``demote`` levels), pipe tables, bullet / numbered lists, fenced code, paragraphs, inline code, bold, italics;
    links keep their text only; images are embedded when ``images(src)`` returns a data URI."""
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    para: list[str] = []

    def flush():
        if para:
            out.append("<p>" + _inline_md(" ".join(para), images) + "</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.startswith("```"):
            flush()
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            out.append("<pre>" + escape("\n".join(lines[i + 1:j])) + "</pre>")
            i = j + 1
            continue
        m = re.match(r"^(#{1,6})\s+(.*)$", stripped)
        if m:
            flush()
            level = min(6, len(m.group(1)) + demote)
            out.append(f"<h{level}>{_inline_md(m.group(2), images)}</h{level}>")
            i += 1
            continue
        if stripped.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                cells = [c.strip() for c in re.split(r"(?<!\\)\|", lines[i].strip().strip("|"))]
                if not all(re.fullmatch(r":?-{2,}:?", c) for c in cells if c):
                    rows.append([c.replace("\\|", "|") for c in cells])
                i += 1
            if rows:
                width = max(len(r) for r in rows)
                table = ["<div class=tablebox><table><thead><tr>"
                         + "".join(f"<th>{_inline_md(c, images)}</th>" for c in rows[0]) + "</tr></thead><tbody>"]
                for r in rows[1:]:
                    r = r + [""] * (width - len(r))
                    table.append("<tr>" + "".join(f"<td{' class=num' if _is_num(c) else ''}>"
                                                  f"{_inline_md(c, images)}</td>" for c in r) + "</tr>")
                table.append("</tbody></table></div>")
                out.append("".join(table))
            continue
        m = re.match(r"^\s*([-*+]|\d+[.)])\s+(.*)$", line)
        if m:
            flush()
            tag = "ol" if m.group(1)[0].isdigit() else "ul"
            items = []
            while i < len(lines):
                m = re.match(r"^\s*([-*+]|\d+[.)])\s+(.*)$", lines[i])
                if m:
                    items.append(m.group(2))
                elif lines[i].strip() and items and lines[i].startswith((" ", "\t")):
                    items[-1] += " " + lines[i].strip()  # continuation line
                else:
                    break
                i += 1
            out.append(f"<{tag}>" + "".join(f"<li>{_inline_md(t, images)}</li>" for t in items) + f"</{tag}>")
            continue
        if not stripped:
            flush()
        else:
            para.append(stripped)
        i += 1
    flush()
    return "\n".join(out)


def demote_markdown(text: str, levels: int = 3) -> str:
    out, fenced = [], False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            fenced = not fenced
        if not fenced and re.match(r"^#{1,6}\s", line):
            line = "#" * levels + line
        out.append(line)
    return "\n".join(out) + "\n"


def image_resolver(folder: Path) -> Callable[[str], Optional[str]]:
    def resolve(src: str) -> Optional[str]:
        p = (folder / src)
        if re.match(r"^[a-z]+:", src) or not p.is_file() or p.suffix.lower() not in MIME:
            return None
        return data_uri(p.read_bytes(), MIME[p.suffix.lower()])

    return resolve
