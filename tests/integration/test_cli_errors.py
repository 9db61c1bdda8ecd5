"""Bad command-line values fail fast: one line ``python -m experiments <command>: error: ...`` naming the flag,
exit status 2, no run folder, before any JAX work (``experiments.common.check_args``)."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from experiments import __main__ as cli

ROOT = Path(__file__).resolve().parents[2]


def run_cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    # JAX_LOG_COMPILES: any compilation would log a line to stderr, so "exactly one line" also means "no compile".
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "JAX_LOG_COMPILES": "1",
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "experiments", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)  # a hang guard only


# What a run of ``python -m experiments`` may cost before it refuses a flag: its imports (MJX, qdax, sklearn), ~10 s of
# CPU on 2 cores. Measured as the child's CPU time (not wall-clock, which doubles under a loaded machine); a compile
# of any of these programs takes minutes of CPU, far above it.
CHILD_CPU_SECONDS = 60

# Two cases run as a real ``python -m experiments`` (the documented promise end to end: one line on stderr, exit 2,
# no compile, no run folder): a typed command's flag (evolve) and a flag read by importing a module from the working
# folder (learn --curriculum, which ``python -m`` puts on sys.path). The others run in-process, below.
SUBPROCESS_CASES = [
    (["evolve", "--generations", "-5"], "--generations"),
    (["learn", "--curriculum", "badmod:factory"], "--curriculum 'badmod:factory'"),
]
IN_PROCESS_CASES = [
    (["features", "--windows", "0"], "--windows"),
    (["coverage", "--generators", "perlin", "nope"], "--generators"),
    (["evolve", "--out", "FILE"], "--out"),
    (["gradient", "RANDOM.npz"], "archive RANDOM.npz"),
    (["learn", "--curriculum", "map", "--plr-capacity", "5"], "--plr-capacity"),
    (["train-base-policy", "--randomise", "mass=0:1"], "--randomise: randomisation.mass"),
]


def _child_cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@pytest.mark.parametrize("args, flag", SUBPROCESS_CASES)
def test_subprocess_one_line_error_before_any_compile(tmp_path, args, flag):
    (tmp_path / "FILE").write_text("not a folder\n")
    make_inputs(tmp_path)
    before = _child_cpu_seconds()
    r = run_cli(args, tmp_path)
    cpu = _child_cpu_seconds() - before
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"python -m experiments {args[0]}: error: {flag}"), r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not (tmp_path / "runs").exists()
    assert cpu < CHILD_CPU_SECONDS, cpu


@pytest.mark.parametrize("args, flag", IN_PROCESS_CASES, ids=[" ".join(a) for a, _ in IN_PROCESS_CASES])
def test_in_process_one_line_error(tmp_path, monkeypatch, capsys, args, flag):
    """The other cases of the subprocess test above, through ``cli.main``: one line, exit 2, no run folder."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))  # badmod
    (tmp_path / "FILE").write_text("not a folder\n")
    make_inputs(tmp_path)
    with pytest.raises(SystemExit) as exc:
        cli.main(args)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert exc.value.code == 2, err
    assert len(lines) == 1 and lines[0].startswith(f"python -m experiments {args[0]}: error: {flag}"), err
    assert "Traceback" not in err and out == ""
    assert not (tmp_path / "runs").exists()


ARCHIVE = ROOT / "docs" / "results" / "exp2_perlin_headings_archive.npz"


def make_inputs(folder: Path) -> None:
    """The bad inputs of issue 59's probe, in ``folder``: ``A.npz`` (a good archive), ``RANDOM.npz`` (random
    bytes), ``NPY.npz`` (an .npy array renamed), ``afile`` (text), ``RUN/`` (a run folder) and ``badmod.py`` (a
    module that raises on import; ``python -m`` and the tests import from ``folder``)."""
    import numpy as np

    (folder / "A.npz").write_bytes(ARCHIVE.read_bytes())
    (folder / "RANDOM.npz").write_bytes(np.random.default_rng(0).bytes(1000))
    np.save(folder / "NPY.npy", np.zeros((4, 4), np.float32))
    (folder / "NPY.npy").rename(folder / "NPY.npz")
    (folder / "afile").write_text("hello\n")
    (folder / "RUN").mkdir(exist_ok=True)
    (folder / "RUN" / "config.json").write_text("{}")
    (folder / "badmod.py").write_text("raise RuntimeError('boom')\n")


def _main(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2, err
    assert len(err.splitlines()) == 1, err
    return err


CASES = [
    # issue 49's probe: each of these used to end in a traceback, or was accepted and ignored, or left a run folder
    (["evolve", "--descriptors", "foo", "bar"], "--descriptors: unknown descriptor 'foo'; choose from"),
    (["gradient"], "give at least one archive.npz"),
    (["gradient", "missing.npz"], "archive missing.npz: no such file"),
    (["gradient", "missing.npz", "--threshold", "2"], "--threshold must be a number in (0, 1]; got 2.0"),
    (["gradient", "missing.npz", "--sample", "-1"], "--sample must be an integer >= 1; got -1"),
    (["gradient", "missing.npz", "--chunk", "0"], "--chunk must be an integer >= 1; got 0"),
    (["gradient", "missing.npz", "--time-limit", "5"], "--time-limit: gradient runs in one piece"),
    (["shares", "--time-limit", "5"], "--time-limit: shares runs in one piece"),
    (["train-gan", "--size", "100"], "--size / the preset's architecture: GanConfig: size=100 must be"),
    (["features", "--windows", "1000"], "--windows must be <= preset 'smoke': 'size' (48); got [1000]"),
    (["train-traversability", "--terrains", "0"], "--terrains must be an integer >= 1; got 0"),
    (["learn", "--threshold", "0"], "--threshold must be a number in (0, 1]; got 0.0"),
    (["report", "missing-run"], "run folder not found: missing-run"),
    (["export", "missing.npz"], "cannot load missing.npz"),
    (["evaluate", "--suite", "v9"], "--suite must be one of v1, v2; got 'v9'"),
    (["evaluate", "--keys", "0"], "--keys must be an integer >= 1; got 0"),
    (["evaluate", "--suite", "v2", "--policy", str(ROOT / "jaxterrain" / "assets" / "base_policy_ant")],
     "--suite v2 holds the levels of robot humanoid (--robot); these policies walk another robot"),
    (["evaluate", "--policy", "missing-policy"], "--policy missing-policy: no policy.msgpack in missing-policy"),
    (["generalise", "missing-run"], "RUN missing-run: no such folder"),
    (["evolve", "--bins", "0"], "--bins must be an integer >= 1; got 0"),
    (["evolve", "--batch-size", "-1"], "--batch-size must be an integer >= 1"),
    (["evolve", "--size", "0"], "--size must be an integer >= 1"),
    (["evolve", "--generator", "nope"], "--generator: unknown generator 'nope'; choose from"),
    (["evolve", "--time-limit", "-1"], "--time-limit must be a finite number > 0"),
    (["evolve", "--attempts", "2", "--best", "3"], "--best must be <= --attempts (2); got 3"),
    (["evolve", "--best", "30"], "--best must be <= --attempts (2); got 30"),  # a preset's value: its flag
    (["evolve", "--out", "FILE/sub"], "--out 'FILE/sub' lies under FILE, which is a file"),
    (["evolve", "--resume", "OTHER"], "--resume 'OTHER' is a run of 'features', not of 'evolve'"),
    (["evolve", "--resume", "FILE"], "--resume 'FILE' is a file"),
    (["evolve", "--config", "BAD.json"], "BAD.json: key 'generations' must be an integer >= 1; got -3"),
    (["evolve", "--config", "MISSING.json"], "--config 'MISSING.json': no such file or folder"),
    (["coverage", "--size", "-64"], "--size must be an integer >= 1"),
    (["coverage", "--generations", "0"], "--generations must be an integer >= 1"),
    (["features", "--terrains", "0"], "--terrains must be an integer >= 1"),
    (["features", "--mutation-steps", "-1"], "--mutation-steps must be an integer >= 0"),
    (["features", "--generators", "cppn", "perlin2"], "--generators: unknown generator 'perlin2'"),
    (["quickstart", "--terrains", "-1"], "--terrains must be an integer >= 1"),
    (["quickstart", "--walk", "-2"], "--walk must be an integer >= 0"),
    (["quickstart", "--out", "FILE"], "--out 'FILE' is a file"),
    (["difficulty-spread", "--heights", "0.5", "-1"], "--heights must be finite numbers > 0"),
    (["difficulty-spread", "--terrains", "0"], "--terrains must be an integer >= 1"),
    (["train-gan", "--steps", "-1"], "--steps must be an integer >= 1"),
    (["train-gan", "--batch-size", "0"], "--batch-size must be an integer >= 1"),
    (["train-gan", "--data", "MISSING"], "--data 'MISSING': no such file or folder"),
    (["train-base-policy", "--num-envs", "0"], "--num-envs must be an integer >= 1"),
    (["train-base-policy", "--robot", "dog"], "--robot: robot must be one of humanoid, ant, got 'dog'"),
    (["evaluate", "--robot", "dog"], "--robot: robot must be one of humanoid, ant, got 'dog'"),
    (["evaluate", "--robot", "ant", "--size", "64"], "--size must be >= 77 pixels for robot ant"),
    (["evaluate", "--engine", "mujoco", "--backend", "warp"], "--backend warp is an MJX backend; --engine mujoco"),
    (["evaluate", "--engine", "mujoco", "--chunk", "4"], "--chunk batches MJX's walks; --engine mujoco walks on CPU"),
    (["evaluate", "--engine", "mujoco", "--workers", "0"], "--workers must be an integer >= 1; got 0"),
    (["evaluate", "--workers", "4"], "--workers sets the CPU processes of --engine mujoco"),
    (["evaluate", "--engine", "mujoco", "--families", "flat", "--generators", "--attempts", "100000", "--workers",
      "1"], "--engine mujoco: 1 policies x 1 terrains x 100000 walks could take up to 28 h"),
    (["evolve", "--fitness", "difficulty"], "--size must be >= 39 pixels for the walker fitness of robot humanoid"),
    (["evolve", "--robot", "ant", "--fitness", "difficulty", "--size", "64"],
     "--size must be >= 77 pixels for the walker fitness of robot ant"),
    (["evolve", "--robot", "dog"], "--robot: robot must be one of humanoid, ant, got 'dog'"),
    (["learn", "--max-evals", "0"], "--max-evals must be an integer >= 1"),
    (["learn", "--curriculum", "accel", "--accel-edits", "0"], "--accel-edits must be an integer >= 1"),
    (["curriculum", "--max-evals", "-2"], "--max-evals must be an integer >= 1"),
    (["curriculum", "--chunks-per-call", "0"], "--chunks-per-call must be an integer >= 1"),
    (["train-base-policy", "--env-steps", "-5"], "--env-steps must be a finite number > 0"),
    (["train-base-policy", "--eval-attempts", "2", "--eval-best", "5"], "--eval-best must be <= --eval-attempts"),
    # issue 59's probe: tracebacks, run folders left behind, flags accepted and ignored
    (["train-gan", "--data", "afile"], "--data afile: DEM afile: unknown extension '(none)'; use one of .tif, .tiff"),
    (["report", "RUN", "--policy", "missing"], "--policy missing: no policy.msgpack in missing"),
    (["evolve", "--generator", "diamond_square", "--size", "100"],
     "--size 100 does not suit generator 'diamond_square' (--generator): size must be a power of two >= 2 (..., 64, "
     "128, 256"),
    (["coverage", "--size", "100"], "--size 100 does not suit generator 'diamond_square' (--generators): size must be"),
    (["gradient", "--band-width", "-1", "A.npz"], "--band-width must be a finite number > 0; got -1.0"),
    (["gradient", "RANDOM.npz"], "archive RANDOM.npz: cannot read it: 'RANDOM.npz': not an .npz archive file"),
    (["gradient", "NPY.npz"], "archive NPY.npz: cannot read it: 'NPY.npz': one .npy array, not an .npz archive"),
    (["gradient", "--rollout-slots", "bogus", "A.npz"], "--rollout-slots must be an integer >= 1, 'all' or 'auto'; got 'bogus'"),
    (["gradient", "--rollout-slots", "0", "A.npz"], "--rollout-slots must be an integer >= 1, 'all' or 'auto'; got '0'"),
    (["gradient", "--reseat", "A.npz"], "--reseat needs --protocol"),
    (["gradient", "--protocol", "paper", "--best", "30", "A.npz"], "--protocol / --attempts / --best"),
    (["curriculum", "--archives", "cppn=missing.npz"], "--archives cppn=missing.npz: archive file 'missing.npz' does "
                                                       "not exist"),
    (["curriculum", "--archives", "cppn=RANDOM.npz"], "--archives cppn=RANDOM.npz: 'RANDOM.npz': not an .npz archive"),
    (["evaluate", "--archive", "RANDOM.npz"], "--archive RANDOM.npz: 'RANDOM.npz': not an .npz archive file"),
    (["evaluate", "--robot", ""], "--robot: robot must be one of humanoid, ant, got ''"),
    # issue 62 item 4: the videos' flags
    (["evaluate", "--video-terrains", "flat:0"], "--video-terrains chooses the terrains of --videos, which is off"),
    (["evaluate", "--videos", "--video-terrains", "slope_up"], "--video-terrains must be FAMILY:LEVEL"),
    (["evaluate", "--videos", "--video-terrains", "slope_up:5"], "--video-terrains: family 'slope_up' is not walked "
                                                                  "here; choose from flat, stairs_up, gaps, gen:perlin"),
    (["evaluate", "--videos", "--video-terrains", "gaps:10"], "--video-terrains: gaps has levels 0 to 9; got 10"),
    (["evaluate", "--videos", "--video-terrains", "flat:1"], "--video-terrains: flat has levels 0 to 0; got 1"),
    (["evaluate", "--videos", "--video-frames", "0"], "--video-frames must be an integer in [1, 4096]; got 0"),
    (["evaluate", "--videos", "--video-width", "8"], "--video-width must be an integer in [16, 4096]; got 8"),
    (["evaluate", "--video-format", "mp4"], "--video-format chooses the files of --videos, which is off: give "
                                            "--videos too"),
    (["learn", "--robot", ""], "--robot: robot must be one of humanoid, ant, got ''"),
    (["learn", "--robot", "dog"], "--robot: robot must be one of humanoid, ant, got 'dog'"),  # before the run folder now
    (["learn", "--curriculum", "badmod:factory"], "--curriculum 'badmod:factory': cannot import it (RuntimeError: boom)"),
    (["learn", "--curriculum", "no_such_module_xyz:f"], "--curriculum 'no_such_module_xyz:f': cannot import it "
                                                        "(ModuleNotFoundError"),
    (["curriculum", "--baseline", "badmod:factory"], "--baseline 'badmod:factory': cannot import it (RuntimeError"),
    (["learn", "--curriculum", "map", "--plr-capacity", "5"],
     "--plr-capacity belongs to --curriculum plr or accel; this run's --curriculum is map"),
    (["learn", "--levels", "3"], "--levels belongs to --curriculum levels; this run's --curriculum is map"),
    (["learn", "--curriculum", "plr", "--accel-edits", "2"], "--accel-edits belongs to --curriculum accel; this run's "
                                                             "--curriculum is plr"),
    (["curriculum", "--plr-min-fill", "0.5"], "--plr-min-fill belongs to --baseline plr or accel; this run's curricula "
                                              "are map, roughness"),
    (["evolve", "--robot", "ant"], "--robot ant: only the walker fitness walks a robot (--fitness difficulty); this "
                                   "run's fitness is 'slope', which walks none"),
    (["evolve", "--robot", "humanoid", "--fitness", "slope"], "--robot humanoid: only the walker fitness walks a robot"),
    # issue 64: observation sets
    (["evolve", "--observation", "perceptive"], "--observation perceptive: only the walker fitness walks a policy"),
    (["evolve", "--spawn", "patch"], "--spawn patch: only the walker fitness walks a policy (--fitness difficulty); "
                                     "this run's fitness is 'slope'"),
    (["train-base-policy", "--scan-noise", "0.1"], "--scan-noise needs --observation perceptive"),
    (["train-base-policy", "--observation", "perceptive", "--scan-noise", "-1"], "--scan-noise must be a finite "
                                                                                "number >= 0"),
    # issue 62: physics randomisation
    (["train-base-policy", "--randomise", "friction=0:1"], "--randomise: randomisation.friction must be (low, high) "
                                                           "with 0 < low <= high"),
    (["learn", "--randomise", "fiction=1"], "--randomise: unknown item 'fiction=1'"),
    (["curriculum", "--randomise", "delay=2:1"], "--randomise: randomisation.delay must be (low, high) env steps"),
    (["evaluate", "--randomise", "push=10"], "--randomise: item push=10: give EVERY:VELOCITY"),
    (["evaluate", "--randomise", "legged-gym", "--videos"], "--videos draws the walks under the nominal physics"),
    (["learn", "--scan-lr-scale", "0.5"], "--scan-lr-scale 0.5 must be 1.0 for a blind walker (it scales Adam's "
                                          "steps on weights reading a height scan: --observation perceptive)"),
    (["curriculum", "--scan-lr-scale", "2"], "--scan-lr-scale 2.0 must be 1.0 for a blind walker"),
    (["learn", "--observation", "perceptive", "--scan-lr-scale", "0"], "--scan-lr-scale must be a finite number > 0"),
    (["perceptive-policy"], "give --out FOLDER or --export-assets"),
    (["perceptive-policy", "--out", "x", "--std-floor", "0"], "--std-floor must be a finite number > 0"),
    # issue 64 item 4: which archive the baselines run on (checked before any archive is read)
    (["curriculum", "--baseline-archive", "nope"], "--baseline-archive must be one of --archives' names (cppn, "
                                                   "diamond_square, gan, perlin, worley); got 'nope'"),
    (["curriculum", "--archives", "steps=A.npz", "mixed=A.npz", "--baseline-archive", "cppn"],
     "--baseline-archive must be one of --archives' names (mixed, steps); got 'cppn'"),
    (["curriculum", "--archives", "steps=A.npz", "mixed=A.npz", "--baseline", "dr"],
     "--baseline runs on --baseline-archive cppn (the default), which is not among --archives' names (mixed, steps)"),
    (["perceptive-policy", "--out", "x", "--robot", "dog"], "--robot: robot must be one of humanoid, ant, got 'dog'"),
    (["perceptive-policy", "--out", "x", "--from", str(ROOT / "jaxterrain" / "assets" / "base_policy_perceptive")],
     "the policy is already perceptive"),
    # flags that were accepted and ignored (the audit after evaluate --time-limit): each refused in one line
    (["gradient", "A.npz", "--attempts", "4"], "--attempts: sets the walks of --protocol, which is not given"),
    (["gradient", "A.npz", "--sample", "5"], "--sample: sets the walks of --protocol, which is not given"),
    (["gradient", "A.npz", "--rollout-slots", "64"], "--rollout-slots: sets the walks of --protocol, which is not"),
    (["gradient", "A.npz", "--seed", "3"], "--seed: sets the walks of --protocol, which is not given"),
    (["shares", "--seed", "3"], "--seed: shares draws nothing at random"),
    (["evolve", "--attempts", "4"], "--attempts: sets the walks of the walker fitness (--fitness difficulty); this "
                                    "run's fitness is 'slope', which walks none"),
    (["evolve", "--protocol", "headings"], "--protocol: sets the walks of the walker fitness"),
    (["evolve", "--backend", "jax"], "--backend: sets the walks of the walker fitness"),
    (["coverage", "--protocol", "paper"], "--protocol: sets the walks of the walker fitness (--fitness difficulty); "
                                          "this run's fitness is 'slope'"),
    (["evaluate", "--archive", "A.npz", "--families", "flat"], "--families: builds the held-out suite; this run "
                                                               "walks --archive A.npz instead"),
    (["evaluate", "--archive", "A.npz", "--size", "256"], "--size: builds the held-out suite; this run walks "
                                                          "--archive A.npz instead"),
    (["evaluate", "--video-frames", "10"], "--video-frames: shapes the videos of --videos, which is off: give "
                                           "--videos too"),
    (["evaluate", "--video-format", "gif"], "--video-format: shapes the videos of --videos, which is off"),
    (["evaluate", "--gl", "egl"], "--gl: shapes the videos of --videos, which is off"),
    (["train-base-policy", "--assets-dir", "x"], "--assets-dir: where --export-assets writes; give --export-assets"),
    (["train-base-policy", "--skip-eval", "--eval-best", "2"], "--eval-best: sets the flat-ground evaluation, which "
                                                               "--skip-eval skips"),
    (["train-gan", "--quality-only", "A.npz", "--steps", "5"], "--steps: --quality-only checks the given weights and "
                                                               "trains nothing"),
    (["train-gan", "--quality-only", "A.npz", "--time-limit", "5"], "--time-limit: --quality-only checks the given "
                                                                    "weights"),
    (["learn", "--resume", "RUN", "--report", "--export-policies"], "--export-policies and --report each write from "
                                                                    "the last checkpoint and stop; give one"),
    (["learn", "--resume", "RUN", "--report", "--time-limit", "5"], "--time-limit: --report trains nothing"),
    (["learn", "--resume", "RUN", "--report", "--devices", "2"], "--devices: --report trains nothing"),
    (["learn", "--resume", "RUN", "--export-policies", "--devices", "1"], "--devices: --export-policies trains "
                                                                          "nothing"),
    (["curriculum", "--resume", "RUN", "--report", "--shard", "0/2"], "--shard: --report writes the tables of every "
                                                                      "treatment and trains nothing"),
    (["curriculum", "--resume", "RUN", "--report", "--devices", "2"], "--devices: --report writes the tables of "
                                                                      "every treatment and trains nothing"),
    (["curriculum", "--archives", "cppn=A.npz", "--combined"], "--combined: the map curriculum on the combination of "
                                                               "several --archives; this run has one (cppn)"),
    (["export", "A.npz", "--format", "png", "npy", "--cell-size", "0.1"], "--cell-size: metres of the obj, stl, mjcf "
                                                                          "files; --format png npy writes heightmap"),
    (["report", "RUN", "--no-videos", "--policy", "missing"], "--policy: shapes the walker videos, which --no-videos "
                                                              "leaves out"),
    (["report", "RUN", "--video-width", "0"], "--video-width must be >= 1, got 0"),  # named --width before
    (["report", "RUN", "--video-steps", "0"], "--video-steps must be >= 1, got 0"),  # named --steps before
    (["quickstart", "--walk", "0", "--attempts", "4"], "--attempts: sets the walks, which --walk 0 leaves out"),
    (["quickstart", "--no-report", "--report-frames", "10"], "--report-frames: sets the report's videos, which "
                                                             "--no-report leaves out"),
]


@pytest.mark.parametrize("argv, message", CASES, ids=[" ".join(a) for a, _ in CASES])
def test_bad_flags_name_the_flag(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "FILE").write_text("not a folder\n")
    (tmp_path / "OTHER").mkdir()
    (tmp_path / "OTHER" / "config.json").write_text(json.dumps({"command": "features", "seed": 0}))
    (tmp_path / "BAD.json").write_text(json.dumps({"generations": -3}))
    make_inputs(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))  # badmod
    if argv[0] not in cli.COMMANDS:
        pytest.skip(f"no command {argv[0]}")
    err = _main(argv, capsys)
    assert err.startswith(f"python -m experiments {argv[0]}: error: "), err
    assert message in err, err
    assert not (tmp_path / "runs").exists()


def test_evaluate_refuses_mp4_videos_without_the_video_extra(tmp_path, monkeypatch, capsys):
    """``--video-format mp4`` where imageio-ffmpeg does not import: one line naming the extra, exit 2, no run folder,
    before any walk."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # the import raises ImportError
    err = _main(["evaluate", "--videos", "--video-format", "mp4"], capsys)
    assert err == ("python -m experiments evaluate: error: --video-format mp4 writes MP4 with imageio-ffmpeg, which is "
                   "not installed: pip install 'jaxterrain[video]'")
    assert not (tmp_path / "runs").exists()


SELECTOR_VALUES = {"terrains_per_chunk": "2", "levels": "3", "levels_init": "1", "levels_promote": "0.9",
                   "levels_demote": "0.5", "plr_capacity": "5", "plr_replay_prob": "0.5", "plr_staleness": "0.5",
                   "plr_temperature": "0.5", "plr_min_fill": "0.5", "accel_generator": "perlin", "accel_edits": "2"}


@pytest.mark.parametrize("field", sorted(SELECTOR_VALUES))
def test_a_curriculum_flag_is_refused_with_another_curriculum_and_taken_with_its_own(field, tmp_path, monkeypatch,
                                                                                     capsys):
    """Every curriculum's own flag (``CurriculumConfig.SELECTOR_FIELDS``), given on the command line, is refused
    with a built-in curriculum that ignores it, naming the curricula it belongs to; with its own (or a --config
    that names its own, whose other curricula's keys are set) it is taken."""
    from experiments.common import flag
    from jaxterrain.curriculum.config import SELECTOR_FIELDS, SELECTORS

    from experiments import learn

    assert set(SELECTOR_VALUES) <= set(SELECTOR_FIELDS)  # the flags of the selectors' params (map's have none)
    assert sorted(learn.selector_overrides(__import__("argparse").Namespace(**dict.fromkeys(SELECTOR_VALUES)))) == \
        sorted(SELECTOR_VALUES)
    monkeypatch.chdir(tmp_path)
    owners = SELECTOR_FIELDS[field]
    other = next(c for c in SELECTORS if c not in owners)
    given = [flag(field), SELECTOR_VALUES[field]]
    err = _main(["learn", "--curriculum", other, *given], capsys)
    assert f"learn: error: {flag(field)} belongs to --curriculum {' or '.join(owners)}; this run's --curriculum is " \
           f"{other}" in err, err
    for argv in (["--curriculum", owners[0]], ["--config", "OWN.json"]):
        config = {**__import__("experiments.learn").learn.PRESETS["smoke"], "curriculum": owners[0]}
        (tmp_path / "OWN.json").write_text(json.dumps(config))
        with pytest.raises(SystemExit) as exit_:
            cli.main(["learn", *argv, *given, "--print-config"])
        assert exit_.value.code == 0, capsys.readouterr().err
        printed = json.loads(capsys.readouterr().out)
        assert str(printed[field]) == SELECTOR_VALUES[field] and printed["curriculum"] == owners[0]
    assert not (tmp_path / "runs").exists()


def test_every_preset_passes_the_checks():
    """The checks by option name accept every shipped preset (they only reject what no command can run)."""
    import importlib

    from experiments import common

    for name, (module_name, _) in cli.COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError:
            continue
        presets = getattr(module, "PRESETS", None)
        for preset, values in (presets.items() if isinstance(presets, dict) else ()):
            if isinstance(values, dict):
                where = lambda k, name=name, preset=preset: f"{name} {preset} {k}"  # noqa: E731
                common.check_rules(values, getattr(module, "RULES", {}), where)
                common.check_values(values, where)


NEEDS = {"gradient": [str(ROOT / "docs" / "results" / "exp2_perlin_headings_archive.npz"),  # required inputs
                      "--protocol", "paper"]}  # gradient's --seed seeds the walks of --protocol (refused without)
LONG_COMMANDS = ["coverage", "curriculum", "evaluate", "evolve", "features", "gradient", "learn", "train-base-policy",
                 "train-gan", "train-traversability"]


@pytest.mark.parametrize("command", LONG_COMMANDS)
def test_every_long_command_takes_the_same_presets_and_prints_its_config(command, tmp_path, capsys):
    """One vocabulary: every long command takes ``smoke``, ``gpu-short``, ``gpu`` and ``paper``.
    ``--print-config``: the preset's settings with the flags given, as JSON, exit status 0, no run folder."""
    from experiments.common import PRESET_NAMES

    for preset in PRESET_NAMES:
        with pytest.raises(SystemExit) as exit_:
            cli.main([command, *NEEDS.get(command, []), "--preset", preset, "--seed", "7", "--print-config",
                      "--out", str(tmp_path / "run")])
        assert exit_.value.code == 0, preset
        config = json.loads(capsys.readouterr().out)
        assert config["command"] == command and config["seed"] == 7 and config["preset"] == preset
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("argv, message", [
    (["--curriculum", "accel", "--accel-generator", "nope"], "learn: --accel-generator must be one of cppn, "),
    (["--curriculum", "levels", "--levels", "3", "--levels-init", "3"], "learn: --levels-init must be in [0, levels - 1"),
    (["--curriculum", "plr", "--plr-capacity", "100000"], "learn: --plr-capacity must be at most "),
    (["--recipe", "wide"], "learn: --recipe / --num-envs (the update's shape): num_envs x unroll_length x num_unrolls "
                           "(40000) must divide epochs_per_chunk x steps_per_epoch (80)"),  # smoke's 80-step chunks
])
def test_learn_refuses_settings_read_against_the_archive_in_one_line_and_leaves_no_run(tmp_path, monkeypatch,
                                                                                     capsys, argv, message):
    """Values checked once the archive is read (the curriculum's config): one line, status 2, the run folder gone."""
    monkeypatch.chdir(tmp_path)
    assert cli.main(["learn", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(message), err
    runs = tmp_path / "runs"
    assert not runs.exists() or not any(runs.iterdir())  # the run folder made for it was removed again


def test_recipes_shape_the_update_and_num_envs_overrides_theirs(capsys):
    """``--recipe NAME`` sets the update's shape from ``jaxterrain.curriculum.RECIPES`` (``paper``: the presets'
    500 x 10 x 8; ``wide``: 4 000 x 10 x 1, the same 40 000 env steps per update), in ``learn`` and ``curriculum``;
    ``--num-envs`` still wins; the curriculum built from it trains with that PPO shape."""
    from experiments import learn
    from jaxterrain.curriculum import FINE_TUNING, RECIPES, presets, recipe, run_config, runner
    from jaxterrain.walker import SPAWNS
    from jaxterrain.walker.layout import BACKEND_CHOICES

    assert presets.RECIPE_NAMES == tuple(RECIPES) and presets.BACKENDS == BACKEND_CHOICES
    assert presets.SPAWNS == SPAWNS
    assert RECIPES["paper"] == {k: getattr(FINE_TUNING, k) for k in RECIPES["paper"]}
    assert {k: v for k, v in learn.PRESETS["gpu-short"].items() if k in RECIPES["paper"]} == RECIPES["paper"]
    steps = lambda r: r["num_envs"] * r["unroll_length"] * r["num_unrolls"]  # noqa: E731
    assert steps(RECIPES["wide"]) == steps(RECIPES["paper"]) == 40_000
    with pytest.raises(ValueError, match="recipe must be one of paper, wide, got 'narrow'"):
        recipe("narrow")

    def printed(*argv):
        with pytest.raises(SystemExit):
            cli.main([*argv, "--print-config"])
        return json.loads(capsys.readouterr().out)

    for command in ("learn", "curriculum"):
        wide = printed(command, "--preset", "gpu-short", "--recipe", "wide")
        assert wide["recipe"] == "wide" and {k: wide[k] for k in RECIPES["wide"]} == RECIPES["wide"], command
    assert printed("learn", "--preset", "gpu-short")["recipe"] == "paper"
    mine = printed("learn", "--preset", "gpu-short", "--recipe", "wide", "--num-envs", "2000")
    assert (mine["num_envs"], mine["num_unrolls"]) == (2000, 1)
    cfg = printed("learn", "--preset", "gpu-short", "--recipe", "wide")
    run = run_config.from_flat({**cfg, "attempts": 20, "best": 5, "headings": 4})  # the archive's protocol
    ppo = runner.curriculum_config(run).ppo
    assert (ppo.num_envs, ppo.unroll_length, ppo.num_unrolls) == (4000, 10, 1)


def test_evaluate_raises_a_presets_size_to_one_the_robot_fits(tmp_path, capsys):
    """A 64-pixel suite is too small for the ant (1.0 + 1.3 m of margins at 4 cm a pixel): a size the user did not
    give (a preset's, a saved config's) becomes the next multiple of 32 that fits, said on stderr (naming the flag)
    and recorded in the run's config; the humanoid keeps 64; a size the user gave is refused instead."""
    from jaxterrain import difficulty
    from jaxterrain.runtime import schema
    from jaxterrain.suite import run_config, runs

    run = schema.replace(run_config.PRESETS["smoke"], {"terrains.size": 64})
    for robot, size in (("ant", 96), ("humanoid", 64)):
        fitted, side = runs.fit_size(run, [difficulty.robot_base_policy(robot)], raise_size=True, note=print)
        assert fitted.terrains.size == side == size, robot
    with pytest.raises(ValueError, match="EvaluateRun.terrains.size must be >= 77 pixels for robot ant"):
        runs.fit_size(run, [difficulty.robot_base_policy("ant")])
    saved = tmp_path / "config.json"
    saved.write_text(json.dumps(run_config.to_flat(run)))
    capsys.readouterr()
    with pytest.raises(SystemExit):
        cli.main(["evaluate", "--config", str(saved), "--robot", "ant", "--print-config"])
    out, err = capsys.readouterr()
    assert json.loads(out)["size"] == 96
    assert "evaluate: --size 96 (the smoke preset's 64 pixels are too small for robot ant)" in err


def test_a_library_field_is_printed_as_its_flag():
    """``learn`` and ``curriculum`` print the library's ``LearnConfig.<field>`` as the flag that sets it, through one
    table (``run_config.FLAT_FIELDS`` and each selector's ``SelectorSpec.flat``, then ``common.flag``)."""
    from experiments import common, learn
    from jaxterrain.curriculum import run_config, selectors

    for key in run_config.FLAT_FIELDS:
        assert learn.flags_in(f"LearnConfig.{run_config.field_of(key)} must be", "map") == f"{common.flag(key)} must be"
    for name in ("map", "roughness", "dr", "levels", "plr", "accel"):
        for key, field in selectors.selector_spec(name).flat.items():
            text = learn.flags_in(f"LearnConfig.curriculum.params.{field} must be", name)
            assert text == f"{common.flag(key)} must be", (name, key)
    assert learn.flags_in("LearnConfig.archive a.npz: 1 filled cell(s)", "map") == "--archive a.npz: 1 filled cell(s)"
