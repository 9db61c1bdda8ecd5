"""Readers of a curriculum run's files, shared by the tests that compare two runs (a population against its
treatments alone, a resumed run against an uninterrupted one)."""

import csv
import json
from pathlib import Path

import numpy as np


def rows(path: Path) -> list[dict]:
    """The rows of a CSV file (``history.csv``, ``sequences.csv``) as dicts of strings."""
    with open(path) as f:
        return list(csv.DictReader(f))


def checkpoint(folder: Path) -> dict:
    """The trial-state leaves of ``folder/checkpoint.npz`` (``{"leaf:...": array}``)."""
    with np.load(folder / "checkpoint.npz") as data:
        return {k: data[k] for k in data.files if k.startswith("leaf:")}


def summary(folder: Path) -> dict:
    """``folder/summary.json`` without its wall time (``seconds``), the part two equal runs share."""
    return {k: v for k, v in json.loads((folder / "summary.json").read_text()).items() if k != "seconds"}
