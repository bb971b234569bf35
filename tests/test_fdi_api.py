"""``fdi``'s public API: ``__all__`` resolves, each public name has a docstring, ``import fdi``
stays light, and the README's example runs and prints what the README shows."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from pathlib import Path

import fdi

ROOT = Path(__file__).resolve().parents[1]


def test_every_exported_name_resolves_and_is_documented() -> None:
    assert len(fdi.__all__) == len(set(fdi.__all__)) >= 20
    for name in fdi.__all__:
        obj = getattr(fdi, name)
        assert obj.__module__.startswith("fdi."), name
        assert (obj.__doc__ or "").strip(), f"fdi.{name} has no docstring"
    assert issubclass(fdi.UsageError, fdi.FdiBridgeError)
    assert "RoverIsolator" in dir(fdi)


def test_an_unknown_name_is_an_attribute_error() -> None:
    try:
        fdi.NoSuchThing  # noqa: B018
    except AttributeError as err:
        assert "NoSuchThing" in str(err)
    else:
        raise AssertionError("fdi.NoSuchThing resolved")


def test_import_fdi_errors_does_not_import_the_estimators() -> None:
    """The drivers import ``fdi.errors``: the package's names are imported on first use."""
    out = subprocess.run(
        [sys.executable, "-c", "import sys, fdi.errors; "
         "print(sorted(m for m in sys.modules if m.startswith('fdi') or m == 'numpy'))"],
        capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "['fdi', 'fdi.errors']"


def test_the_readme_example_prints_what_the_readme_shows() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## The estimators as a library", 1)[1].split("\n## ", 1)[0]
    code, shown = re.findall(r"```(?:python)?\n(.*?)```", section, re.S)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    assert buf.getvalue() == shown
    assert "replace" in shown
