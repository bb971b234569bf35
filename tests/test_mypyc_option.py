"""The compiled build is an option: without ``FDI_BRIDGE_MYPYC=1`` setup.py adds no extension
(the wheel stays pure Python, tests/test_wheel.py builds it), and what it would compile exists."""

from __future__ import annotations

import runpy
from pathlib import Path
from typing import Any

import pytest
import setuptools

ROOT = Path(__file__).resolve().parents[1]


def _setup_kwargs(monkeypatch: pytest.MonkeyPatch) -> tuple[dict[str, Any], list[str]]:
    got: dict[str, Any] = {}
    monkeypatch.setattr(setuptools, "setup", lambda **kw: got.update(kw))
    ns = runpy.run_path(str(ROOT / "setup.py"), run_name="setup")
    return got, list(ns["MYPYC_MODULES"])


def test_pure_python_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("FDI_BRIDGE_MYPYC", raising=False)
    kwargs, modules = _setup_kwargs(monkeypatch)
    assert kwargs == {"ext_modules": []}
    assert modules and all((ROOT / m).is_file() for m in modules), modules
