"""Which shipped curriculum runs trained with the compact-on-tiles bug (exp3.md, "Training bug"), and the share
of their env steps that ran on another trial's tile.

The bug: the solo runner's compact blocks (``curriculum.run_live``, from commit a3b77de, 2026-11-27 17:29 UTC)
computed the running trials as a smaller batch laid out on tiles ``0..R-1``, while their envs stayed where they
were. Envs only "stay where they were" across blocks since bfe08b4 (2026-11-29 03:06 UTC: the trials' env states
ride from block to block, and into checkpoints); before it every block restarted every trial's envs on the tile that
block's layout gave it (``make_block``: ``restart`` True, env states zeroed), so a compact block placed each trial's
envs on its own terrain. An env walks on another trial's tile only with all of: a tiled walker (``backend`` warp,
or ``overlap`` on), ``compact`` on (the default; a config.json without the key reads as on), a training commit with
both ``run_live`` and bfe08b4 (and without the fix), and a block that starts with some trials done and some
running, i.e. a trial whose map emptied (or that hit ``max_evals``) before another trial's last chunk. The last
condition is read from each treatment's ``history.csv`` (a trial's rows are its chunks, so a trial of n rows was
done from chunk n on): a chunk c is "mixed" when some trial has fewer than c + 1 rows and another more than c. A
run without a mixed chunk never computed fewer rows than all its trials (``population.live_rows`` is then every
row); a run whose training commits all restart envs per block never kept an env on a stale tile: either way its
share is exactly 0.

For a treatment where all conditions hold, the share's upper bound counts every env step of every running trial in
every mixed chunk over all its env steps (a trial moved at a block's start walks on another tile at most until its
envs' next reset: a terrain switch, or an episode's end, <= ``episode_length`` steps later; the bound counts
neither, nor the block boundaries, which are not recorded). Training commits: the ``provenance.jsonl`` nearest the
treatment (commands of its ``--shard``), else :data:`STATED`. One known gap: exp2_paper_bootstrap's diamond-square
ran chunks 350-525 at aaa6dda with run_live uncommitted in the tree (exp2_paper.md), which the commit column shows as
without run_live; it restarted envs per block all the same (aaa6dda predates bfe08b4).

    PYTHONPATH=. python docs/results/compact_tiles_audit.py            # the table (markdown) on stdout
    PYTHONPATH=. python docs/results/compact_tiles_audit.py --csv docs/results/compact_tiles_audit.csv

CPU, reads the shipped files and ``git`` (for the commits' ancestry) only.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import subprocess
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent
RUN_LIVE = "a3b77de"  # curriculum.run_live: compact blocks on (2026-11-27 17:29 UTC)
CARRIED = "bfe08b4"  # env states ride from block to block (2026-11-29 03:06 UTC); before, every block restarted them
POPULATION = "40e5078"  # the batched-population runner (2026-11-29 08:40 UTC)
STATED = {"exp3_gpushort/diamond_square-map": "f14867a", "exp3_gpushort/gan-map": "f14867a"}
"""Commits stated on a page where provenance.jsonl has none (exp3.md, Set-up: diamond-square and GAN map at f14867a)."""
RUNS = ["exp3_gpushort", "exp3b_gpushort", "exp3c_gpushort", "wide_gpushort", "ant_gpushort/learn",
        "exp2_gpushort", "exp2_headings", "exp2_paper", "exp2_all", "exp2_bootstrap", "exp2_paper_bootstrap",
        "exp2_paper_cppn_map", "exp2_paper_combined_map", "exp2_paper_cppn_roughness"]


def treatments(run: Path) -> list[Path]:
    """The treatment folders of a run folder: those with a history.csv (the run itself for a ``learn`` run, and
    folders of further runs below it)."""
    return sorted(p.parent for p in run.rglob("history.csv"))


def config_of(folder: Path, run: Path) -> dict:
    """The treatment's config.json, else its run's (a treatment inherits the curriculum command's settings)."""
    for f in (folder / "config.json", run / "config.json"):
        if f.exists():
            return json.loads(f.read_text())
    return {}


def chunks_per_trial(folder: Path) -> list[int]:
    """Rows of each trial in history.csv: the chunks it ran (done from then on)."""
    with open(folder / "history.csv") as f:
        n = Counter(int(r["trial"]) for r in csv.DictReader(f))
    return [n[t] for t in sorted(n)]


def mixed_share(chunks: list[int]) -> tuple[int, float]:
    """``(mixed chunks, upper bound of the env-step share)``: chunks c with a trial done (fewer than c + 1 chunks)
    and another running (more than c); the bound is the running trials' chunks in those over all trials' chunks
    (every chunk has the same env steps)."""
    total, exposed, mixed = sum(chunks), 0, 0
    for c in range(max(chunks)):
        running = sum(1 for n in chunks if n > c)
        if running < len(chunks):
            mixed += 1
            exposed += running
    return mixed, exposed / total if total else 0.0


def has(commit: str, ancestor: str) -> str:
    """"yes" / "no" / "?": whether ``commit`` contains ``ancestor`` (git merge-base --is-ancestor)."""
    sha = commit.split()[0]
    out = subprocess.run(["git", "merge-base", "--is-ancestor", ancestor, sha], cwd=ROOT, capture_output=True)
    return {0: "yes", 1: "no"}.get(out.returncode, "?")


def training_commits(run: Path, folder: Path, run_cfg: dict) -> list[str]:
    """Commits of the commands that trained ``folder`` (the nearest ``provenance.jsonl`` from ``folder`` up to
    ``run``; ``report`` false; with ``--shard I/N`` in the run's file those whose treatment index ``t % N == I``,
    the curriculum command's order: archives sorted by name, combined, the cppn baselines)."""
    near = [d for d in [folder, *folder.parents] if d == run or run in d.parents]  # folder up to run
    provs = [d / "provenance.jsonl" for d in near if (d / "provenance.jsonl").exists()]
    if not provs:
        return []
    prov = provs[0]
    order = None
    if "archives" in run_cfg and prov == run / "provenance.jsonl":
        names = sorted(run_cfg["archives"])
        order = [f"{n}-map" for n in names] + (["combined-map"] if len(names) > 1 else [])
        order += [f"cppn-{b}" for b in run_cfg.get("baseline") or []]
    out = []
    for line in prov.read_text().splitlines():
        rec = json.loads(line)
        opts = rec.get("options", {})
        if opts.get("report") or rec.get("command") not in ("learn", "curriculum"):
            continue
        shard = opts.get("shard")
        if shard and order is not None and folder.name in order and order.index(folder.name) % shard[1] != shard[0]:
            continue
        if rec["commit"] not in out:
            out.append(rec["commit"])
    return out


def audit() -> list[dict]:
    rows = []
    for name in RUNS:
        run = ROOT / name
        if not run.exists():
            continue
        run_cfg = json.loads((run / "config.json").read_text()) if (run / "config.json").exists() else {}
        for folder in treatments(run):
            cfg = config_of(folder, run)
            chunks = chunks_per_trial(folder)
            mixed, share = mixed_share(chunks)
            commits = training_commits(run, folder, run_cfg) or [
                c for c in [STATED.get(str(folder.relative_to(ROOT)))] if c]
            tiled = cfg.get("backend") in ("warp", "auto") or bool(cfg.get("overlap"))  # auto: warp where it imports
            compact = cfg.get("compact", True) is not False  # absent: read as on (run_config.LEGACY)
            live = [has(c, RUN_LIVE) for c in commits]
            carried = [has(c, CARRIED) for c in commits]
            population = [c for c in commits if has(c, POPULATION) == "yes"]
            buggy = any(a != "no" and b != "no" for a, b in zip(live, carried)) or not commits
            affected = mixed > 0 and compact and tiled and buggy
            rows.append(dict(
                treatment=str(folder.relative_to(ROOT)), backend=cfg.get("backend"), overlap=bool(cfg.get("overlap")),
                compact=cfg.get("compact"),
                runner=("solo" if commits else "solo (no commit recorded)") if not population else "solo or population",
                commits=" ".join(c.split()[0][:7] for c in commits) or "?", run_live=" ".join(live) or "?",
                envs_carried=" ".join(carried) or "?", trials=len(chunks), chunks_min=min(chunks),
                chunks_max=max(chunks), mixed_chunks=mixed, share_bound=round(share if affected else 0.0, 4),
                affected="yes (bound)" if affected else "no"))
    return rows


def markdown(rows: list[dict]) -> str:
    head = ["treatment", "backend", "overlap", "compact", "training commits (run_live? envs carried?)",
            "chunks per trial", "mixed chunks", "env steps on another trial's tile"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        commits = ", ".join(f"{c} ({a}, {b})" for c, a, b in zip(r["commits"].split(), r["run_live"].split(),
                                                                  r["envs_carried"].split())) or "none recorded"
        span = str(r["chunks_min"]) if r["chunks_min"] == r["chunks_max"] else f"{r['chunks_min']}-{r['chunks_max']}"
        share = "0 (exact)" if r["affected"] == "no" else f"<= {100 * r['share_bound']:.1f} % (bound)"
        out.append(f"| {r['treatment']} | {r['backend']} | {r['overlap']} | {r['compact']} | {commits} | {span} | "
                   f"{r['mixed_chunks']} | {share} |")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", default=None, help="also write the rows here")
    args = parser.parse_args()
    rows = audit()
    if args.csv:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        Path(args.csv).write_text(buf.getvalue())
    print(markdown(rows))


if __name__ == "__main__":
    main()
