"""An archive on a report page: an interactive fitness heatmap (HTML, plus the script that shows a cell's terrain
on hover and pins it on click) built from an :class:`~jaxterrain.report.archives.ArchiveView`. Used by
:mod:`jaxterrain.report.page`."""

from __future__ import annotations

import base64
import json

import numpy as np

from jaxterrain.report.archives import ArchiveView
from jaxterrain.report.markdown import escape

__all__ = ["CMAP", "archive_html", "SCRIPT"]

CMAP = "viridis_r"  # as the archive figures of the commands: dark = high fitness = easy


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


def archive_html(v: ArchiveView, uid: str) -> str:
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
<div class=archive id="{uid}" data-first="{'' if first is None else first}" data-d0="{escape(d0)}" data-d1="{escape(d1)}">
 <p class=stats>{b} x {b} cells, {len(v.cells)} filled (coverage {v.coverage:.1f} %), QD score {v.qd_score:.2f},
  generator(s) {escape(', '.join(v.generator_names))}; heightmaps {v.shape[0]} x {v.shape[1]}.
  Colour: the archive's fitness, dark = high (the walker's fitness is the normalised distance walked: dark = easy;
  difficulty = 1 - fitness).
  <b class="pick key" data-pick=E></b> <b class="pick key" data-pick=M></b> <b class="pick key" data-pick=H></b>
  mark the highest-, median- and lowest-fitness elites (easiest, median, hardest).</p>
 <div class=archrow>
  <div class=axes>
   <div class=ylab style="height:{grid_w + 2}px">
    <span>{y1:g}</span><span class=name>{escape(d1)}</span><span>{y0:g}</span></div>
   <div>
    <div class=grid style="{grid_style}">{''.join(cells)}</div>
    <div class=xlab style="width:{grid_w}px"><span>{x0:g}</span><span>{escape(d0)}</span><span>{x1:g}</span></div>
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


SCRIPT = """
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
