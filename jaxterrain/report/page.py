"""Stage 4 of a report: one self-contained HTML page and its Markdown twin.

    write_report(["runs/quickstart-x", "runs/evolve-y"], "runs/report-z")
    # -> runs/report-z/report.html (images base64-embedded, inline CSS / JS, no network)
    #    runs/report-z/report.md  (+ report_files/: the same figures, heatmaps, thumbnails and GIFs as files)

For every run folder (:func:`jaxterrain.report.collect.scan`): its ``config.json``, every table (CSV / TSV as
tables, Markdown rendered), every figure, each archive as a fitness heatmap whose cells show their terrain's
thumbnail, fitness and descriptors on hover (click pins a cell; a switch shows all thumbnails in the grid), and
videos of the policy walking the easiest, the median and the hardest terrain of the archive
(:mod:`jaxterrain.report.render`), an evaluation's videos of walkers beside the base policy (``videos/videos.csv``
and its GIFs or MP4s, :func:`jaxterrain.report.compare.write_videos`) with their terrain and fitness, then small text
files verbatim and the remaining files by name and size.
Nothing on the page refers to a network address.

This module builds the page section by section; :mod:`jaxterrain.report.markdown` renders the tables and Markdown,
:mod:`jaxterrain.report.heatmap` each archive's interactive heatmap.
"""
from __future__ import annotations

import csv
import datetime as _dt
import json
import re
import time
from pathlib import Path
from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from jaxterrain import qd as A
from jaxterrain.report import archives as AV
from jaxterrain.report import collect
from jaxterrain.report.compare import VIDEO_COLUMNS
from jaxterrain.report import render as R
from jaxterrain.report.heatmap import SCRIPT, CMAP, archive_html  # noqa: F401

# Tables and Markdown live in jaxterrain.report.markdown; these names stay importable from here.
from jaxterrain.report.markdown import (  # noqa: F401
    MIME,
    MAX_ROWS,
    data_uri,
    demote_markdown,
    escape,
    html_table,
    image_resolver,
    md_table,
    markdown_to_html,
    read_table,
)
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text

__all__ = ["write_report", "markdown_to_html", "read_table", "MAX_ROWS"]


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


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
        cap = f"<b>{escape(vid.label)}</b>: {escape(vid.caption)}"
        if vid.outcome:
            cap += f"<br>{escape(vid.outcome)}"
        if vid.gif is not None:
            out.append(f'<figure><img alt="{escape(vid.label)} walk" src="{data_uri(vid.gif, "image/gif")}">'
                       f"<figcaption>{cap}</figcaption></figure>")
        else:
            out.append(f"<figure><div class=skipped>No video: {escape(vid.reason)}</div><figcaption>{cap}"
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

    t_start = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / collect.MARKER).write_text("written by jaxterrain.report; skipped when a report scans its run\n")
    assets = _Assets(out / "report_files")
    assets.folder.mkdir(exist_ok=True)
    scans = [collect.scan(r, exclude=(out,)) for r in runs]
    extra = {Path(k).resolve(): v for k, v in (extra_terrains or {}).items()}

    # archives, then every video in one batch (one compile per terrain shape)
    views, walks = _load_archives(scans, thumb, videos, extra, progress)
    if videos:
        gl_ok, render_line, made = _make_videos(walks.wanted, seed, video_steps, video_frames, video_size, policy,
                                                progress)
    else:
        gl_ok, render_line, made = False, "Videos not requested.", []

    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    h: list[str] = []
    md: list[str] = [f"# {title}", "", f"Generated {now} from {len(scans)} run folder(s). {render_line}", ""]
    for r, run in enumerate(scans):
        _run_section(h, md, r, run, views, walks.at, made, assets)
    elapsed = time.perf_counter() - t_start
    page = _page_html(title, now, scans, elapsed, gl_ok, render_line, h)
    path = atomic_write_text(out / "report.html", page)
    atomic_write_text(out / "report.md", "\n".join(md).rstrip("\n") + "\n")
    return path


class _Walks(NamedTuple):
    """The terrains to walk: ``wanted`` ``[(label, caption, heightmap [H, W])]`` in video order, and ``at``: the
    indices into it of each archive's picks (key ``(run, archive)``) and of each run's extra terrains
    (``(run, -1)``)."""

    wanted: list
    at: dict


def _load_archives(scans, thumb: int, videos: bool, extra: dict, progress) -> tuple[dict, _Walks]:
    """Load and view every archive of every run (key ``(run, archive)``: an ``ArchiveView``, or the error as text)
    and gather the terrains to walk: each archive's picks, then the run's extra terrains."""

    views: dict[tuple[int, int], object] = {}
    walks = _Walks([], {})
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
                maps = AV.elite_heightmaps(arch, list(v.picks.values()))
                _want(walks, (r, a), [(label, f"cell {cell}, archive fitness {float(arch.fitness[cell]):.3f}", hm)
                                      for (label, cell), hm in zip(v.picks.items(), maps)])
        if videos and run.root.resolve() in extra:
            _want(walks, (r, -1), [(label, caption, np.asarray(hm, np.float32))
                                   for label, caption, hm in extra[run.root.resolve()]])
    return views, walks


def _want(walks: _Walks, where: tuple[int, int], terrains: list) -> None:
    walks.at[where] = list(range(len(walks.wanted), len(walks.wanted) + len(terrains)))
    walks.wanted.extend(terrains)


def _make_videos(wanted: list, seed: int, steps: int, frames: int, size: tuple[int, int], policy, progress):
    """``(gl_ok, the line that says how the videos were made or why not, [Video])``."""
    import jax


    gl_ok, gl_text = R.gl_status()
    render_line = (f"Videos: {gl_text}, replaying states recorded from MJX rollouts." if gl_ok
                   else f"Renders skipped: {gl_text}.")
    made = R.make_videos(wanted, jax.random.key(seed), steps=steps, frames=frames, width=size[0], height=size[1],
                         policy=policy, progress=progress)
    return gl_ok, render_line, made


def _run_section(h: list[str], md: list[str], r: int, run, views: dict, walks_at: dict, made: list,
                 assets: _Assets) -> None:
    """Append run ``r``'s section to the page ``h`` and its Markdown twin ``md``."""
    prefix = f"r{r}"
    h.append(f'<section class=run id="run-{r}"><h2>{escape(run.name)}</h2><p class=path>{escape(str(run.root))}</p>')
    md += [f"## {run.name}", "", f"`{run.root}`", ""]
    if run.config is not None:
        rows = _config_rows(run.config)
        h.append(f"<details><summary>config.json ({len(rows) - 1} options)</summary>"
                 f"{html_table(rows)}</details>")
        md += ["### Configuration (config.json)", "", md_table(rows)]
    _tables(h, md, run)
    shown = _evaluation_videos(h, md, run, assets, prefix)
    _figures(h, md, run, assets, prefix, skip=shown)
    if run.archives:
        h.append("<h3>Archives</h3>")
        md += ["### Archives", ""]
    for a, path in enumerate(run.archives):
        _archive(h, md, run.rel(path), views[r, a], f"arch-{r}-{a}", assets, prefix,
                 [made[i] for i in walks_at[r, a]] if (r, a) in walks_at else None)
    if (r, -1) in walks_at:
        vids = [made[i] for i in walks_at[r, -1]]
        h.append("<h3>Walks</h3>" + _videos_html(vids))
        md += ["### Walks", "", _videos_md(vids, assets, f"{prefix}_walk")]
    _other_files(h, md, run)
    h.append("</section>")


def _tables(h: list[str], md: list[str], run) -> None:
    """Every table of the run: CSV / TSV as tables, Markdown rendered (its images embedded)."""
    if run.tables:
        h.append("<h3>Tables</h3>")
        md += ["### Tables", ""]
    for path in run.tables:
        rel = run.rel(path)
        h.append(f"<h4>{escape(rel)}</h4>")
        md += [f"#### {rel}", ""]
        try:
            if path.suffix.lower() == ".md":
                text = path.read_text(encoding="utf-8", errors="replace")
                resolve = image_resolver(path.parent)
                h.append(f"<div class=md>{markdown_to_html(text, demote=4, images=resolve)}</div>")
                md.append(demote_markdown(re.sub(r"!\[([^\]]*)\]\([^)]*\)", r"[image: \1]", text), 4))
            else:
                rows = read_table(path)
                h.append(html_table(rows))
                md.append(md_table(rows))
        except (OSError, csv.Error) as err:
            h.append(f"<p class=warn>cannot read {escape(rel)}: {escape(str(err))}</p>")
            md.append(f"cannot read {rel}: {err}\n")


def _evaluation_videos(h: list[str], md: list[str], run, assets: _Assets, prefix: str) -> set:
    """The videos of an evaluation (``evaluate --videos``: a ``videos.csv`` beside ``<walker>/<family>_L<level>.gif``
    and / or ``.mp4``, :func:`jaxterrain.report.compare.write_videos`), each with its terrain and both policies'
    fitness: a GIF embedded as an image as ever (its MP4, with ``--video-format both``, copied to ``report_files/``
    and linked), an MP4 alone embedded in a ``<video>`` element (a link in the Markdown twin); returns the files
    shown, which the figures then leave out."""
    shown: set = set()
    for table in run.tables:
        if table.name != "videos.csv":
            continue
        try:
            with open(table, newline="") as fh:
                reader = csv.DictReader(fh)
                rows = list(reader) if set(VIDEO_COLUMNS) - {"mp4"} <= set(reader.fieldnames or []) else []
        except (OSError, csv.Error, UnicodeDecodeError):
            continue
        rows = [r for r in rows if (table.parent / r["file"]).is_file()]
        if not rows:
            continue
        rel = run.rel(table.parent)
        h.append(f"<h3>Videos ({escape(rel)})</h3><p>Each walker beside the base policy on one terrain: one walk "
                 "along +x from the same start (of several tried, the one the walker went farthest from), recorded "
                 "from the physics the evaluation used and replayed by MuJoCo's renderer; the fitness is the "
                 "level's mean under the evaluation's protocol.</p>"
                 "<div class=videos>")
        md += [f"### Videos ({rel})", "", "Each walker beside the base policy on one terrain: one walk along +x from "
               "the same start (of several tried, the one the walker went farthest from); the fitness is the "
               "level's mean under the evaluation's protocol.", ""]
        for r in rows:
            video = table.parent / r["file"]
            mp4 = table.parent / r["mp4"] if r.get("mp4") else None
            shown.update(p for p in (video, mp4) if p is not None)
            unit = "" if r["unit"] in ("", "-") else f" ({r['value']} {r['unit']})"
            cap = (f"{r['walker']} on {r['family']} level {r['level']}{unit}: level fitness {r['walker_level_fitness']}"
                   f" vs the base policy's {r['base_level_fitness']}; this walk: {r['walker_walk']}"
                   + (f" / {r['base_walk']}" if r["walker"] != "base" else "")
                   + f" (start {r['start']} of {r['starts']}: the walker's farthest)")
            data = video.read_bytes()
            asset = assets.add(f"{prefix}_video_{r['file']}", data)
            if video.suffix.lower() == ".mp4":  # an MP4 alone: a <video> in the page, a link in the Markdown
                h.append(f'<figure style="max-width:none"><video controls autoplay loop muted playsinline '
                         f'title="{escape(r["file"])}" src="{data_uri(data, "video/mp4")}"></video>'
                         f"<figcaption>{escape(cap)}</figcaption></figure>")
                md += [f"[{r['file']} (MP4)]({asset})", "", f"*{cap}*", ""]
                continue
            link = md_link = ""
            if mp4 is not None and mp4.is_file():  # both: the GIF as ever, the MP4 beside it as a file
                extra = assets.add(f"{prefix}_video_{r['mp4']}", mp4.read_bytes())
                link = f' (<a href="{escape(extra)}">MP4</a>, {_size(mp4.stat().st_size)})'
                md_link = f" ([MP4]({extra}))"
            h.append(f'<figure style="max-width:none"><img alt="{escape(r["file"])}" '
                     f'src="{data_uri(data, "image/gif")}"><figcaption>{escape(cap)}{link}</figcaption></figure>')
            md += [f"![{r['file']}]({asset})", "", f"*{cap}*{md_link}", ""]
        h.append("</div>")
    return shown


def _figures(h: list[str], md: list[str], run, assets: _Assets, prefix: str, skip: set = frozenset()) -> None:
    """Every figure of the run (but those in ``skip``), embedded in the page and copied for the Markdown twin."""
    figures = [p for p in run.figures if p not in skip]
    if figures:
        h.append("<h3>Figures</h3>")
        md += ["### Figures", ""]
    for path in figures:
        rel = run.rel(path)
        data = path.read_bytes()
        h.append(f'<figure><img alt="{escape(rel)}" src="{data_uri(data, MIME[path.suffix.lower()])}">'
                 f"<figcaption>{escape(rel)}</figcaption></figure>")
        md += [f"![{rel}]({assets.add(f'{prefix}_{rel}', data)})", "", f"*{rel}*", ""]


def _archive(h: list[str], md: list[str], rel: str, v, uid: str, assets: _Assets, prefix: str,
             vids: Optional[list]) -> None:
    """One archive: the heatmap (or why it cannot be shown), its picks' table in the Markdown twin, and the walks
    ``vids`` on its picks (None: no walks)."""

    h.append(f"<h4>{escape(rel)}</h4>")
    md += [f"#### {rel}", ""]
    if isinstance(v, str):
        h.append(f"<p class=warn>cannot show this archive: {escape(v)}</p>")
        md.append(f"cannot show this archive: {v}\n")
        return
    h.append(archive_html(v, uid))
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
    if vids is not None:
        h.append("<h5>The policy on the easiest, median and hardest elite</h5>" + _videos_html(vids))
        md += ["Walks of the policy:", "", _videos_md(vids, assets, f"{prefix}_{rel}")]


def _other_files(h: list[str], md: list[str], run) -> None:
    """Small text files verbatim, the remaining files by name and size."""
    if run.texts or run.others:
        h.append("<h3>Other files</h3>")
        md += ["### Other files", ""]
    for path in run.texts:
        rel = run.rel(path)
        text = path.read_text(encoding="utf-8", errors="replace")
        h.append(f"<details><summary>{escape(rel)}</summary><pre>{escape(text)}</pre></details>")
        md += [f"<details><summary>{rel}</summary>", "", "```", text.rstrip("\n"), "```", "", "</details>", ""]
    if run.others:
        h.append("<ul class=files>" + "".join(f"<li>{escape(run.rel(p))} ({_size(p.stat().st_size)})</li>"
                                              for p in run.others) + "</ul>")
        md += [f"- `{run.rel(p)}` ({_size(p.stat().st_size)})" for p in run.others] + [""]


def _page_html(title: str, now: str, scans, elapsed: float, gl_ok: bool, render_line: str, body: list[str]) -> str:
    """The whole page: header with one link per run, the render status, the runs' sections, the script."""
    nav = " ".join(f'<a href="#run-{r}">{escape(run.name)}</a>' for r, run in enumerate(scans))
    status_cls = "ok" if gl_ok else "warn"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{escape(title)}</title><style>{_STYLE}</style></head>
<body><header><h1>{escape(title)}</h1>
<p>Generated {escape(now)} from {len(scans)} run folder(s) in {elapsed:.0f} s. Self-contained: every image is embedded.</p>
<nav>{nav}</nav></header>
<main><p class={status_cls}>{escape(render_line)}</p>
{''.join(body)}
</main><script>{SCRIPT}</script></body></html>
"""
