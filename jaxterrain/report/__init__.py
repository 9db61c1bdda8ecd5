"""What a researcher looks at: one self-contained HTML page (and its Markdown twin) per set of run folders, with
every table and figure, each archive as an interactive heatmap of terrain thumbnails, and videos of the walker.

    from jaxterrain import report
    report.write_report(["runs/evolve-x"], "runs/evolve-x/report")   # report.html, report.md, report_files/

One module per stage:

- :mod:`~jaxterrain.report.collect`: what a run folder holds (tables, figures, archives, config, other files);
- :mod:`~jaxterrain.report.archives`: an archive's filled cells with thumbnails, and its easy / medium / hard elites;
- :mod:`~jaxterrain.report.render`: MJX rollouts recorded, replayed by MuJoCo's offscreen renderer into GIFs
  (``MUJOCO_GL``: osmesa on a CPU machine, egl on a GPU one; :func:`~jaxterrain.report.render.setup_gl`);
- :mod:`~jaxterrain.report.encode`: frames to the bytes of a GIF (Pillow) or an MP4 (H.264, the optional extra
  ``pip install 'jaxterrain[video]'``);
- :mod:`~jaxterrain.report.compare`: a walker beside the base policy on video, two panels in step (``evaluate
  --videos``);
- :mod:`~jaxterrain.report.page`: the HTML page and the Markdown twin, with
  :mod:`~jaxterrain.report.markdown` (tables, Markdown to HTML) and :mod:`~jaxterrain.report.heatmap` (an archive as
  an interactive heatmap).

Importing this package does not import mujoco, so MUJOCO_GL can still be chosen after it (``render.setup_gl``).
"""

from jaxterrain.report.page import write_report

__all__ = ["write_report"]
