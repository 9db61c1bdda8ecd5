"""Stage 4 of a report: one self-contained HTML page and its Markdown twin.

    write_report(["runs/quickstart-x", "runs/evolve-y"], "runs/report-z")
    # -> runs/report-z/report.html (images base64-embedded, inline CSS / JS, no network)
    #    runs/report-z/report.md  (+ report_files/: the same figures, heatmaps, thumbnails and GIFs as files)

For every run folder (:func:`jaxterrain.report.collect.scan`): its ``config.json``, every table (CSV / TSV as
tables, Markdown rendered), every figure, each archive as a fitness heatmap whose cells show their terrain's
thumbnail, fitness and descriptors on hover (click pins a cell; a switch shows all thumbnails in the grid), and
videos of the policy walking the easiest, the median and the hardest terrain of the archive
(:mod:`jaxterrain.report.render`), then small text files verbatim and the remaining files by name and size.
Nothing on the page refers to a network address.
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import html
import io
import json
import re
import time
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from jaxterrain.report import collect
from jaxterrain.report.archives import ArchiveView

__all__ = ["write_report", "markdown_to_html", "read_table", "MAX_ROWS"]

MAX_ROWS = 500
"""Rows of a table shown on the page; longer tables are cut there (the note names the file)."""

_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".gif": "image/gif",
         ".svg": "image/svg+xml", ".webp": "image/webp"}
_E = html.escape
CMAP = "viridis_r"  # as the archive figures of the commands: dark = high fitness = easy


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


# ----------------------------------------------------------------------------------------------------------------
# Tables and Markdown
# ----------------------------------------------------------------------------------------------------------------
def read_table(path: Path) -> list[list[str]]:
    """Rows of a CSV / TSV file (header first); ragged rows are kept as they are."""
    text = path.read_text(encoding="utf-8", errors="replace")
    return [row for row in csv.reader(io.StringIO(text), delimiter="\t" if path.suffix.lower() == ".tsv" else ",")]


def _html_table(rows: Sequence[Sequence[str]], max_rows: int = MAX_ROWS, header: bool = True) -> str:
    if not rows:
        return "<p class=note>(empty table)</p>"
    width = max(len(r) for r in rows)
    head, body = (rows[0], rows[1:]) if header else ([], rows)
    out = ["<div class=tablebox><table>"]
    if head:
        out.append("<thead><tr>" + "".join(f"<th>{_E(c)}</th>" for c in head) + "</tr></thead>")
    out.append("<tbody>")
    for r in body[:max_rows]:
        cells = list(r) + [""] * (width - len(r))
        out.append("<tr>" + "".join(f"<td{' class=num' if _is_num(c) else ''}>{_E(c)}</td>" for c in cells)
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


def _md_table(rows: Sequence[Sequence[str]], max_rows: int = MAX_ROWS) -> str:
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
            out.append(f"<code>{_E(part[1:-1])}</code>")
            continue

        def image(m):
            src = images(m.group(2)) if images else None
            return f'<img alt="{_E(m.group(1))}" src="{src}">' if src else _E(f"[image: {m.group(1) or m.group(2)}]")

        tokens = []

        def keep(m):
            tokens.append(image(m))
            return f"\x00{len(tokens) - 1}\x00"

        s = re.sub(r"!\[([^\]]*)\]\(([^)\s]+)[^)]*\)", keep, part)
        s = re.sub(r"\[([^\]]+)\]\([^)]*\)", r"\1", s)  # links: text only
        s = _E(s)
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
            out.append("<pre>" + _E("\n".join(lines[i + 1:j])) + "</pre>")
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


def _demote_markdown(text: str, levels: int = 3) -> str:
    out, fenced = [], False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            fenced = not fenced
        if not fenced and re.match(r"^#{1,6}\s", line):
            line = "#" * levels + line
        out.append(line)
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------------------------------
# Archives
# ----------------------------------------------------------------------------------------------------------------
def _hex_colours(values: np.ndarray, lo: float, hi: float) -> list[str]:
    import matplotlib

    cmap = matplotlib.colormaps[CMAP]
    t = np.clip((np.asarray(values, np.float64) - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
    return [matplotlib.colors.to_hex(cmap(v)) for v in t]


def _legend_gradient() -> str:
    import matplotlib

    cmap = matplotlib.colormaps[CMAP]
    stops = ", ".join(matplotlib.colors.to_hex(cmap(t)) for t in np.linspace(0, 1, 9))
    return f"linear-gradient(to right, {stops})"


def _archive_html(v: ArchiveView, uid: str) -> str:
    b = v.bins
    px = int(max(6, min(40, 520 // max(b, 1))))
    fit = np.array([c.fitness for c in v.cells]) if v.cells else np.zeros(0)
    lo, hi = 0.0, 1.0  # the walker's fitness, on the scale of the commands' own figures (viridis_r, 0..1)
    if fit.size and (fit.min() < 0 or fit.max() > 1):  # another fitness: its own range
        lo, hi = float(fit.min()), float(fit.max())
        if hi - lo < 1e-9:
            lo, hi = lo - 0.5, hi + 0.5
    colours = _hex_colours(fit, lo, hi)
    by_cell = {c.cell: k for k, c in enumerate(v.cells)}
    pick_of = {cell: label for label, cell in v.picks.items()}
    d0, d1 = v.descriptor_names
    (x0, x1), (y0, y1) = v.ranges
    cells = []
    for row in range(b - 1, -1, -1):  # top row = highest bin of descriptor 1
        for col in range(b):
            cell = row * b + col
            k = by_cell.get(cell)
            if k is None:
                cells.append("<i></i>")
                continue
            c = v.cells[k]
            label = pick_of.get(cell)
            mark = f' class=pick data-pick="{label[0].upper()}"' if label else ""
            cells.append(f'<b data-k={k}{mark} style="background-color:{colours[k]}" '
                         f'title="cell {cell}: fitness {c.fitness:.3f}"></b>')
    data = [{"c": c.cell, "f": round(c.fitness, 4), "d": [float(f"{x:.4g}") for x in c.descriptors],
             "b": list(c.bins), "g": c.generator,
             "h": [round(c.heights[0], 3), round(c.heights[1], 3)], "t": base64.b64encode(c.thumbnail).decode("ascii")}
            for c in v.cells]
    first = by_cell.get(v.picks.get("easy", -1), 0 if v.cells else None)
    grid_w = b * px
    grid_style = f"grid-template-columns:repeat({b},{px}px);grid-auto-rows:{px}px;width:{grid_w}px"
    return f"""
<div class=archive id="{uid}" data-first="{'' if first is None else first}" data-d0="{_E(d0)}" data-d1="{_E(d1)}">
 <p class=stats>{b} x {b} cells, {len(v.cells)} filled (coverage {v.coverage:.1f} %), QD score {v.qd_score:.2f},
  generator(s) {_E(', '.join(v.generator_names))}; heightmaps {v.shape[0]} x {v.shape[1]}.
  Colour: the archive's fitness, dark = high (the walker's fitness is the normalised distance walked: dark = easy;
  difficulty = 1 - fitness).
  <b class="pick key" data-pick=E></b> <b class="pick key" data-pick=M></b> <b class="pick key" data-pick=H></b>
  mark the highest-, median- and lowest-fitness elites (easiest, median, hardest).</p>
 <div class=archrow>
  <div class=axes>
   <div class=ylab style="height:{grid_w + 2}px">
    <span>{y1:g}</span><span class=name>{_E(d1)}</span><span>{y0:g}</span></div>
   <div>
    <div class=grid style="{grid_style}">{''.join(cells)}</div>
    <div class=xlab style="width:{grid_w}px"><span>{x0:g}</span><span>{_E(d0)}</span><span>{x1:g}</span></div>
    <div class=legend style="width:{grid_w}px"><span>{lo:.3g}</span>
     <span class=bar style="background:{_legend_gradient()}"></span><span>{hi:.3g}</span></div>
    <label class=switch><input type=checkbox class=thumbs> show every cell's thumbnail</label>
   </div>
  </div>
  <div class=panel><img alt="terrain thumbnail" width=192 height=192><div class=info>Hover over a cell to see its
   terrain; click to pin it.</div><p class=note>Thumbnail: the map's lowest point dark blue, its highest white, relief
   shaded from the north-west; heights in heightmap units (metres at the default scale).</p></div>
 </div>
 <script type="application/json" class=cells>{json.dumps(data, separators=(",", ":"))}</script>
</div>"""


_SCRIPT = """
document.querySelectorAll('.archive').forEach(function (box) {
  var data = JSON.parse(box.querySelector('script.cells').textContent);
  var img = box.querySelector('.panel img'), info = box.querySelector('.panel .info');
  var grid = box.querySelector('.grid'), pinned = null;
  var d0 = box.dataset.d0, d1 = box.dataset.d1;
  function show(k) {
    var e = data[k];
    if (!e) return;
    img.src = 'data:image/jpeg;base64,' + e.t;
    img.style.visibility = 'visible';
    info.textContent = '';
    [['cell', e.c + ' (bins ' + e.b[0] + ', ' + e.b[1] + ')'], ['fitness', e.f.toFixed(3)],
     ['difficulty', (1 - e.f).toFixed(3)], [d0, e.d[0]], [d1, e.d[1]], ['generator', e.g],
     ['heights', e.h[0] + ' to ' + e.h[1]]].forEach(function (kv) {
      var row = document.createElement('div');
      var key = document.createElement('span'); key.textContent = kv[0];
      var val = document.createElement('span'); val.textContent = kv[1];
      row.appendChild(key); row.appendChild(val); info.appendChild(row);
    });
  }
  function cellOf(ev) { var el = ev.target.closest('[data-k]'); return el && grid.contains(el) ? el : null; }
  grid.addEventListener('mouseover', function (ev) { var el = cellOf(ev); if (el && !pinned) show(+el.dataset.k); });
  grid.addEventListener('click', function (ev) {
    var el = cellOf(ev); if (!el) return;
    if (pinned) pinned.classList.remove('pinned');
    pinned = pinned === el ? null : el;
    if (pinned) pinned.classList.add('pinned');
    show(+el.dataset.k);
  });
  box.querySelector('input.thumbs').addEventListener('change', function (ev) {
    grid.querySelectorAll('[data-k]').forEach(function (el) {
      el.style.backgroundImage = ev.target.checked ? 'url(data:image/jpeg;base64,' + data[+el.dataset.k].t + ')' : '';
    });
  });
  if (box.dataset.first !== '') show(+box.dataset.first);
});
"""

_STYLE = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d2327;
 background:#f6f7f9}
main{max-width:1320px;margin:0 auto;padding:8px 24px 48px}
header{background:#20303f;color:#eef2f5;padding:18px 24px}
header h1{margin:0 0 4px;font-size:22px}
header p{margin:2px 0;color:#c9d3dc}
nav a{color:#9fd0ff;margin-right:14px}
a{color:#0b62a4}
section.run{background:#fff;border:1px solid #dde2e7;border-radius:8px;padding:4px 20px 16px;margin:20px 0}
h2{font-size:19px;border-bottom:2px solid #e3e7eb;padding-bottom:4px}
h3{font-size:16px;margin:22px 0 6px;color:#30465b}
h4{font-size:14px;margin:16px 0 4px;font-family:ui-monospace,Menlo,Consolas,monospace;color:#444}
h5,h6{font-size:13px;margin:10px 0 4px}
.path{font-family:ui-monospace,Menlo,Consolas,monospace;color:#666;margin-top:0}
.note{color:#777;font-size:12px;margin:2px 0}
.warn{background:#fff4e5;border-left:4px solid #f0a030;padding:6px 10px;margin:8px 0}
.ok{background:#eaf6ec;border-left:4px solid #3c9a52;padding:6px 10px;margin:8px 0}
.tablebox{max-height:420px;overflow:auto;border:1px solid #e3e7eb;display:inline-block;max-width:100%}
table{border-collapse:collapse;font-size:12.5px}
th,td{border:1px solid #e3e7eb;padding:2px 8px;text-align:left;white-space:nowrap}
th{background:#f0f3f6;position:sticky;top:0}
td.num{text-align:right;font-variant-numeric:tabular-nums}
tbody tr:nth-child(even){background:#fafbfc}
figure{margin:10px 0 16px}
figure img{max-width:100%;border:1px solid #e3e7eb;background:#fff}
figcaption{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:12px;color:#555}
pre{background:#f3f5f7;padding:8px;overflow:auto;max-height:360px;font-size:12px}
details summary{cursor:pointer;color:#30465b;font-weight:600;margin:6px 0}
.archive{margin:6px 0 10px}
.archrow{display:flex;gap:24px;align-items:flex-start;flex-wrap:wrap}
.axes{display:flex;gap:6px}
.ylab{display:flex;flex-direction:column;justify-content:space-between;align-items:flex-end;font-size:12px;
 color:#444;width:44px}
.ylab .name{writing-mode:vertical-rl;transform:rotate(180deg);align-self:center}
.grid{display:grid;background:#eceff2;border:1px solid #c9d0d6}
.grid i,.grid b{display:block;box-sizing:border-box;background-size:cover}
.grid b{cursor:pointer;outline:0 solid #fff}
.grid b:hover,.grid b.pinned{outline:2px solid #ff3b30;z-index:2;position:relative}
b.pick{position:relative;outline:2px solid #ff7a00;z-index:1}
b.pick::after{content:attr(data-pick);position:absolute;inset:0;display:flex;align-items:center;
 justify-content:center;font:bold 11px sans-serif;color:#fff;text-shadow:0 0 2px #000,0 0 2px #000,0 0 3px #000}
b.pick.key{display:inline-block;width:15px;height:15px;background:#555;vertical-align:middle;outline-width:1px}
.xlab,.legend{display:flex;justify-content:space-between;font-size:12px;color:#444;margin-top:3px}
.legend .bar{flex:1;height:10px;margin:4px 8px}
.switch{font-size:12px;color:#444;display:block;margin-top:6px}
.panel{width:240px;border:1px solid #dde2e7;border-radius:6px;padding:10px;background:#fbfcfd}
.panel img{width:192px;height:192px;visibility:hidden;image-rendering:auto;border:1px solid #ccc;display:block;
 margin:0 auto 8px}
.panel .info div{display:flex;justify-content:space-between;font-size:12.5px;border-bottom:1px dotted #ddd}
.panel .info span:first-child{color:#666;margin-right:10px}
.videos{display:flex;gap:16px;flex-wrap:wrap}
.videos figure{margin:4px 0;max-width:340px}
.videos figcaption{font-family:inherit;font-size:12.5px}
.skipped{width:320px;min-height:80px;border:1px dashed #c9a25b;background:#fffaf0;color:#7a5200;font-size:12px;
 padding:8px;box-sizing:border-box}
ul.files{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:12px}
"""


# ----------------------------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------------------------
class _Assets:
    """Files of the Markdown twin under ``report_files/``."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.names: set[str] = set()

    def add(self, name: str, data: bytes) -> str:
        from jaxterrain.io import atomic_write_bytes

        name = re.sub(r"[^A-Za-z0-9._-]+", "_", name)
        base, n = name, 1
        while name in self.names:
            stem, dot, ext = base.rpartition(".")
            name, n = f"{stem}_{n}.{ext}" if dot else f"{base}_{n}", n + 1
        self.names.add(name)
        atomic_write_bytes(self.folder / name, data)
        return f"{self.folder.name}/{name}"


def _videos_html(videos) -> str:
    out = ["<div class=videos>"]
    for vid in videos:
        cap = f"<b>{_E(vid.label)}</b>: {_E(vid.caption)}"
        if vid.outcome:
            cap += f"<br>{_E(vid.outcome)}"
        if vid.gif is not None:
            out.append(f'<figure><img alt="{_E(vid.label)} walk" src="{_data_uri(vid.gif, "image/gif")}">'
                       f"<figcaption>{cap}</figcaption></figure>")
        else:
            out.append(f"<figure><div class=skipped>No video: {_E(vid.reason)}</div><figcaption>{cap}"
                       f"</figcaption></figure>")
    out.append("</div>")
    return "".join(out)


def _videos_md(videos, assets: _Assets, prefix: str) -> str:
    lines = []
    for vid in videos:
        text = f"- **{vid.label}**: {vid.caption}" + (f"; {vid.outcome}" if vid.outcome else "")
        if vid.gif is not None:
            lines.append(text + f"\n\n  ![{vid.label} walk]({assets.add(f'{prefix}_{vid.label}.gif', vid.gif)})")
        else:
            lines.append(text + f". No video: {vid.reason}")
    return "\n".join(lines) + "\n"


def _config_rows(config: dict) -> list[list[str]]:
    rows = [["option", "value"]]
    for k in sorted(config):
        v = config[k]
        rows.append([str(k), v if isinstance(v, str) else json.dumps(v)])
    return rows


def write_report(runs: Sequence[str | Path], out: str | Path, *, title: str = "jaxterrain report",
                 videos: bool = True, video_steps: int = 1000, video_frames: int = 60,
                 video_size: tuple[int, int] = (320, 240), thumb: int = 64, seed: int = 0, policy=None,
                 extra_terrains: Optional[dict] = None, progress: Callable[[str], None] = print) -> Path:
    """Write ``out/report.html`` and ``out/report.md`` (+ ``out/report_files/``) for the run folders ``runs``.

    ``videos=False`` leaves the walks out; otherwise each archive gets videos of the policy (default: the shipped
    base policy; ``policy`` = a callable obs -> action) walking its easiest, median and hardest elite, at most
    ``video_steps`` env steps each, ``video_frames`` frames of ``video_size`` (width, height) pixels.
    ``extra_terrains`` maps a run folder to ``[(label, caption, heightmap [H, W] in [0, 1]), ...]`` to walk in that
    run's section besides its archives (the quickstart passes its walked terrains). ``thumb`` is the thumbnail side
    in pixels. Failures of the renders or of one archive are reported on the page, never raised. Returns the path
    of ``report.html``.
    """
    from jaxterrain import archive as A
    from jaxterrain.io import atomic_write_text
    from jaxterrain.report import archives as AV
    from jaxterrain.report import render as R

    t_start = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / collect.MARKER).write_text("written by jaxterrain.report; skipped when a report scans its run\n")
    assets = _Assets(out / "report_files")
    assets.folder.mkdir(exist_ok=True)
    scans = [collect.scan(r, exclude=(out,)) for r in runs]
    extra = {Path(k).resolve(): v for k, v in (extra_terrains or {}).items()}

    # archives, then every video in one batch (one compile per terrain shape)
    views: dict[tuple[int, int], object] = {}
    wanted: list[tuple[str, str, np.ndarray]] = []
    wanted_at: dict[tuple[int, int], list[int]] = {}
    for r, run in enumerate(scans):
        for a, path in enumerate(run.archives):
            try:
                arch = A.load(path)
                views[r, a] = v = AV.view(arch, thumb=thumb)
            except Exception as err:  # noqa: BLE001 - shown on the page
                views[r, a] = f"{type(err).__name__}: {err}"
                continue
            progress(f"archive {run.rel(path)}: {len(v.cells)} elites")
            if videos and v.picks:
                cells = list(v.picks.values())
                maps = AV.elite_heightmaps(arch, cells)
                wanted_at[r, a] = []
                for (label, cell), hm in zip(v.picks.items(), maps):
                    wanted_at[r, a].append(len(wanted))
                    wanted.append((label, f"cell {cell}, archive fitness {float(arch.fitness[cell]):.3f}", hm))
        if videos and run.root.resolve() in extra:
            wanted_at[r, -1] = []
            for label, caption, hm in extra[run.root.resolve()]:
                wanted_at[r, -1].append(len(wanted))
                wanted.append((label, caption, np.asarray(hm, np.float32)))
    if videos:
        gl_ok, gl_text = R.gl_status()
        render_line = (f"Videos: {gl_text}, replaying states recorded from MJX rollouts." if gl_ok
                       else f"Renders skipped: {gl_text}.")
        import jax

        made = R.make_videos(wanted, jax.random.key(seed), steps=video_steps, frames=video_frames,
                             width=video_size[0], height=video_size[1], policy=policy, progress=progress)
    else:
        gl_ok, render_line, made = False, "Videos not requested.", []

    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    h: list[str] = []
    md: list[str] = [f"# {title}", "", f"Generated {now} from {len(scans)} run folder(s). {render_line}", ""]
    nav = " ".join(f'<a href="#run-{r}">{_E(run.name)}</a>' for r, run in enumerate(scans))
    for r, run in enumerate(scans):
        prefix = f"r{r}"
        h.append(f'<section class=run id="run-{r}"><h2>{_E(run.name)}</h2><p class=path>{_E(str(run.root))}</p>')
        md += [f"## {run.name}", "", f"`{run.root}`", ""]
        if run.config is not None:
            rows = _config_rows(run.config)
            h.append(f"<details><summary>config.json ({len(rows) - 1} options)</summary>"
                     f"{_html_table(rows)}</details>")
            md += ["### Configuration (config.json)", "", _md_table(rows)]
        if run.tables:
            h.append("<h3>Tables</h3>")
            md += ["### Tables", ""]
        for path in run.tables:
            rel = run.rel(path)
            h.append(f"<h4>{_E(rel)}</h4>")
            md += [f"#### {rel}", ""]
            try:
                if path.suffix.lower() == ".md":
                    text = path.read_text(encoding="utf-8", errors="replace")
                    resolve = _image_resolver(path.parent)
                    h.append(f"<div class=md>{markdown_to_html(text, demote=4, images=resolve)}</div>")
                    md.append(_demote_markdown(re.sub(r"!\[([^\]]*)\]\([^)]*\)", r"[image: \1]", text), 4))
                else:
                    rows = read_table(path)
                    h.append(_html_table(rows))
                    md.append(_md_table(rows))
            except (OSError, csv.Error) as err:
                h.append(f"<p class=warn>cannot read {_E(rel)}: {_E(str(err))}</p>")
                md.append(f"cannot read {rel}: {err}\n")
        if run.figures:
            h.append("<h3>Figures</h3>")
            md += ["### Figures", ""]
        for path in run.figures:
            rel = run.rel(path)
            data = path.read_bytes()
            h.append(f'<figure><img alt="{_E(rel)}" src="{_data_uri(data, _MIME[path.suffix.lower()])}">'
                     f"<figcaption>{_E(rel)}</figcaption></figure>")
            md += [f"![{rel}]({assets.add(f'{prefix}_{rel}', data)})", "", f"*{rel}*", ""]
        if run.archives:
            h.append("<h3>Archives</h3>")
            md += ["### Archives", ""]
        for a, path in enumerate(run.archives):
            rel = run.rel(path)
            h.append(f"<h4>{_E(rel)}</h4>")
            md += [f"#### {rel}", ""]
            v = views[r, a]
            if isinstance(v, str):
                h.append(f"<p class=warn>cannot show this archive: {_E(v)}</p>")
                md.append(f"cannot show this archive: {v}\n")
                continue
            h.append(_archive_html(v, f"arch-{r}-{a}"))
            md += [f"{v.bins} x {v.bins} cells, {len(v.cells)} filled (coverage {v.coverage:.1f} %), QD score "
                   f"{v.qd_score:.2f}; E / M / H mark the easiest, median and hardest elites.", "",
                   f"![fitness heatmap of {rel}]({assets.add(f'{prefix}_{rel}_heatmap.png', AV.heatmap_png(v))})",
                   ""]
            if v.picks:
                by_cell = {c.cell: c for c in v.cells}
                rows = ["| pick | cell | fitness | " + " | ".join(v.descriptor_names) + " | generator | terrain |",
                        "|---|---|---|---|---|---|---|"]
                for label, cell in v.picks.items():
                    c = by_cell[cell]
                    img = assets.add(f"{prefix}_{rel}_{label}.jpg", c.thumbnail)
                    rows.append(f"| {label} | {cell} | {c.fitness:.3f} | {c.descriptors[0]:.4g} | "
                                f"{c.descriptors[1]:.4g} | {c.generator} | ![{label}]({img}) |")
                md += rows + [""]
            if (r, a) in wanted_at:
                vids = [made[i] for i in wanted_at[r, a]]
                h.append("<h5>The policy on the easiest, median and hardest elite</h5>" + _videos_html(vids))
                md += ["Walks of the policy:", "", _videos_md(vids, assets, f"{prefix}_{rel}")]
        if (r, -1) in wanted_at:
            vids = [made[i] for i in wanted_at[r, -1]]
            h.append("<h3>Walks</h3>" + _videos_html(vids))
            md += ["### Walks", "", _videos_md(vids, assets, f"{prefix}_walk")]
        if run.texts or run.others:
            h.append("<h3>Other files</h3>")
            md += ["### Other files", ""]
        for path in run.texts:
            rel = run.rel(path)
            text = path.read_text(encoding="utf-8", errors="replace")
            h.append(f"<details><summary>{_E(rel)}</summary><pre>{_E(text)}</pre></details>")
            md += [f"<details><summary>{rel}</summary>", "", "```", text.rstrip("\n"), "```", "", "</details>", ""]
        if run.others:
            h.append("<ul class=files>" + "".join(f"<li>{_E(run.rel(p))} ({_size(p.stat().st_size)})</li>"
                                                  for p in run.others) + "</ul>")
            md += [f"- `{run.rel(p)}` ({_size(p.stat().st_size)})" for p in run.others] + [""]
        h.append("</section>")

    elapsed = time.perf_counter() - t_start
    status_cls = "ok" if gl_ok else "warn"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_E(title)}</title><style>{_STYLE}</style></head>
<body><header><h1>{_E(title)}</h1>
<p>Generated {_E(now)} from {len(scans)} run folder(s) in {elapsed:.0f} s. Self-contained: every image is embedded.</p>
<nav>{nav}</nav></header>
<main><p class={status_cls}>{_E(render_line)}</p>
{''.join(h)}
</main><script>{_SCRIPT}</script></body></html>
"""
    path = atomic_write_text(out / "report.html", page)
    atomic_write_text(out / "report.md", "\n".join(md).rstrip("\n") + "\n")
    return path


def _image_resolver(folder: Path) -> Callable[[str], Optional[str]]:
    def resolve(src: str) -> Optional[str]:
        p = (folder / src)
        if re.match(r"^[a-z]+:", src) or not p.is_file() or p.suffix.lower() not in _MIME:
            return None
        return _data_uri(p.read_bytes(), _MIME[p.suffix.lower()])

    return resolve
