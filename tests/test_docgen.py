"""Shell completion and the man page, both generated from the parser (issue 17, optional part):
the completion script is loaded into a real bash and asked for completions as bash asks; the
man page is rendered by groff with warnings on, and names every command, option and example."""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from firmware_host import cli
from firmware_host.cli import main
from firmware_host.commands.docgen import commands

BASH = shutil.which("bash")
GROFF = shutil.which("groff")


@pytest.fixture(scope="module")
def script(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("completion") / "fdi-bridge.bash"
    assert main(["completion", "bash", "--out", str(path)]) == 0
    return path


def complete(script: Path, *words: str) -> list[str]:
    """What bash offers for the last of ``words`` (``COMP_WORDS``/``COMP_CWORD`` as bash sets
    them when TAB is pressed)."""
    assert BASH is not None
    quoted = " ".join("'" + w.replace("'", "'\\''") + "'" for w in ("fdi-bridge", *words))
    code = (f"source '{script}'\nCOMP_WORDS=({quoted})\nCOMP_CWORD=$((${{#COMP_WORDS[@]}} - 1))"
            "\n_fdi_bridge\nprintf '%s\\n' \"${COMPREPLY[@]}\"\n")
    out = subprocess.run([BASH, "--norc", "--noprofile", "-c", code], capture_output=True,
                         text=True, timeout=30, check=True)
    return [w for w in out.stdout.splitlines() if w]


@pytest.mark.skipif(BASH is None, reason="no bash on this machine")
@pytest.mark.parametrize(("words", "expected"), [
    (("re",), ["replay", "record"]),
    (("sim", ""), list(cli.SIM_COMMANDS)),
    (("demo", "r"), [k for k in cli.DEMO_COMMANDS if k.startswith("r")]),  # rover, rov
    (("-v", "sim", "rov", "--pl"), ["--plant"]),
    (("sim", "rov", "--plant", ""), ["nomoto", "nonlinear"]),
    (("record", "/dev/ttyUSB0", "--parity", ""), ["N", "E", "O", "M", "S"]),
    (("config", ""), ["check", "show"]),
    (("config", "check", ""), []),  # the file: bash's own file names (complete -o default)
    (("replay", "--config", ""), []),  # a value: file names
    (("completion", ""), ["bash"]),
    (("eval", "--su"), ["--suite"]),
])
def test_bash_completes_from_the_parser(script: Path, words: tuple[str, ...],
                                        expected: list[str]) -> None:
    assert complete(script, *words) == expected


@pytest.mark.skipif(BASH is None, reason="no bash on this machine")
def test_every_command_and_option_is_completed(script: Path) -> None:
    tops = complete(script, "")
    assert tops == [*cli.COMMANDS, "sim"]
    top = cli.build_parser(None)
    subs = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    for name in ("replay", "record", "fleet", "bench"):
        flags = {f for a in subs.choices[name]._actions for f in a.option_strings
                 if f.startswith("--")}
        assert set(complete(script, name, "--")) == flags, name


def test_every_command_has_a_section_option_and_example(tmp_path: Path) -> None:
    page_path = tmp_path / "fdi-bridge.1"
    assert main(["man", "--out", str(page_path)]) == 0
    page = page_path.read_text(encoding="utf-8")
    assert page.startswith(".TH FDI\\-BRIDGE 1 ")
    docs = commands(cli.parser_tree())
    for d in docs[1:]:
        section = page.split(f".SS fdi\\-bridge {d.path.replace('-', chr(92) + '-')}\n", 1)
        assert len(section) == 2, d.path
        body = section[1].split(".SS ", 1)[0]
        key = d.path
        if key in cli.EXAMPLES:
            assert cli.EXAMPLES[key].replace("-", "\\-") in body, key
        for o in d.options:
            if o.flags and not {"-h", "-v", "-q", "--log-level"} & set(o.flags):
                assert f"\\fB{o.flags[-1].replace('-', chr(92) + '-')}\\fR" in body, (key, o)
    # defaults as --help shows them
    replay = page.split(".SS fdi\\-bridge replay\n", 1)[1].split(".SS ", 1)[0]
    assert "(default: 0.0)" in replay
    for code in ("0", "1", "2", "130"):
        assert f".TP\n\\fB{code}\\fR\n" in page


@pytest.mark.skipif(GROFF is None, reason="no groff on this machine")
def test_man_page_renders_without_warnings(tmp_path: Path) -> None:
    assert GROFF is not None
    page_path = tmp_path / "fdi-bridge.1"
    assert main(["man", "--out", str(page_path)]) == 0
    out = subprocess.run([GROFF, "-man", "-Tutf8", "-ww", "-z", str(page_path)],
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 0 and out.stderr == ""
    text = subprocess.run([GROFF, "-man", "-Tascii", str(page_path)], capture_output=True,
                          text=True, timeout=60, check=True).stdout
    text = re.sub(".\x08", "", text)  # no overstrike bold
    assert "fdi-bridge sim insgnss-report" in text and "EXIT STATUS" in text


def test_printed_to_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["completion", "bash"]) == 0
    assert "complete -o default -F _fdi_bridge fdi-bridge" in capsys.readouterr().out
    assert main(["man"]) == 0
    assert capsys.readouterr().out.startswith(".TH FDI\\-BRIDGE 1")


def test_a_bad_out_path_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as info:
        main(["man", "--out", str(tmp_path / "missing" / "x.1")])
    assert info.value.code == 2
