"""The library decides what it computes from its arguments, never from environment variables (issue 60): the only
``JAXTERRAIN_*`` variables it reads are the multi-host launcher's process topology (``runtime.sharding.initialize``)
and the commit a run records when the tree has no git (``runtime.provenance``)."""

from __future__ import annotations

import re
from pathlib import Path

import jax
import pytest

from jaxterrain.rl import collect as ppo_collect
from jaxterrain.rl.config import PPOConfig
from jaxterrain.runtime import sharding

PACKAGE = Path(__file__).resolve().parents[1] / "jaxterrain"
ALLOWED = {"JAXTERRAIN_COORDINATOR", "JAXTERRAIN_NUM_PROCESSES", "JAXTERRAIN_PROCESS_ID", "JAXTERRAIN_COMMIT"}


def test_the_library_reads_only_the_topology_and_commit_variables():
    read = set()
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text()
        read |= set(re.findall(r"environ(?:\.get)?\s*[\[(]\s*[\"'](JAXTERRAIN_\w+)", text))
        read |= set(re.findall(r"[\"'](JAXTERRAIN_\w+)[\"']\s+in\s+os\.environ", text))
        read |= set(re.findall(r"getenv\(\s*[\"'](JAXTERRAIN_\w+)", text))
        for name in re.findall(r"^\w+_ENV\s*=\s*[\"'](JAXTERRAIN_\w+)[\"']", text, re.M):  # named constants
            read.add(name)
    assert read and read <= ALLOWED, sorted(read - ALLOWED)


def test_split_and_collect_are_arguments_not_environment(monkeypatch):
    """``JAXTERRAIN_SPLIT`` / ``JAXTERRAIN_PPO_COLLECT`` of earlier versions change nothing; ``split=`` (map_rows,
    difficulty, qd) and ``collect=`` (PPO's update) choose, and a bad value is one ValueError naming it."""
    mesh = sharding.make_mesh(1)
    monkeypatch.setenv("JAXTERRAIN_SPLIT", "dispatch")
    monkeypatch.setenv("JAXTERRAIN_PPO_COLLECT", "partition")
    assert sharding.default_split(mesh) == "shard_map"  # CPU devices
    config = PPOConfig(num_envs=4)
    assert ppo_collect.collect_mode(mesh, config) == "shard_map"
    assert ppo_collect.collect_mode(mesh, config, collect="partition") == "partition"
    with pytest.raises(ValueError, match="collect must be one of"):
        ppo_collect.collect_mode(mesh, config, collect="bogus")
    f = sharding.map_rows(lambda x: x * 2, mesh, split="dispatch")
    assert float(f(jax.numpy.ones((3,)))[2]) == 2.0
    with pytest.raises(ValueError, match="split must be one of"):
        sharding.map_rows(lambda x: x, mesh, split="bogus")
