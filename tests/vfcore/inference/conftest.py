"""Shared fixtures for the inference tests: a synthetic GAW and a cheap fake forward model."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from inf_helpers import FakeSimulator, synthetic_gaw  # noqa: E402


@pytest.fixture
def fake_sim():
    return FakeSimulator()


@pytest.fixture
def obs_gaw():
    return synthetic_gaw()
