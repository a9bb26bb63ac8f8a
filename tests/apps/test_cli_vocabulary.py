"""One command-line vocabulary: every default in --help, --version, the same --workers default
everywhere, and nothing left behind (not even a folder) by a command that fails."""

import argparse
import re

import pytest

from handeye_drake.apps.cli import main, make_parser


def _subparsers(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                yield from ((f"{name} {n}", s) for n, s in _subparsers(sub))


def test_every_default_is_in_the_help():
    """Each option with a default shows it in the --help text (its own words or the
    formatter's "(default: ...)")."""
    missing, checked = [], 0
    for name, sub in _subparsers(make_parser()):
        formatter = sub._get_formatter()
        for action in sub._actions:
            if not action.option_strings or any(action.default is v for v in (
                    None, False, argparse.SUPPRESS)) or isinstance(
                    action, (argparse._StoreTrueAction, argparse._HelpAction)):
                continue
            checked += 1
            text = " ".join(formatter._format_action(action).split())
            if "default" not in text.lower():
                missing.append(f"{name} {action.option_strings[0]}")
    assert checked > 40 and missing == []
    calibrate = dict(_subparsers(make_parser()))["calibrate"]
    help_text = " ".join(calibrate.format_help().split())
    assert re.search(r"--seed SEED seed of the hold-out split \(default: 0\)", help_text)
    assert "(default: camera_optical_frame)" in help_text


def test_version(capsys):
    assert main(["--version"]) == 0
    assert re.fullmatch(r"handeye-drake \S+\n", capsys.readouterr().out)


def test_workers_default_is_the_same_everywhere():
    defaults = {}
    for name, sub in _subparsers(make_parser()):
        for action in sub._actions:
            if "--workers" in action.option_strings:
                defaults[name] = action.default
    assert len(defaults) >= 3 and len(set(defaults.values())) == 1, defaults


@pytest.mark.parametrize("argv", [
    ["calibrate", "--robot", "/nonexistent/robot.tum", "--camera", "/nonexistent/camera.tum"],
    ["calibrate", "--images", "/nonexistent/dir", "--robot", "/nonexistent/robot.tum",
     "--target", "chessboard:9x6:0.02"],
])
def test_a_failed_command_leaves_no_folder(tmp_path, argv, capsys):
    out = tmp_path / "new" / "deeper"
    assert main([*argv, "--out", str(out)]) == 2
    assert "error:" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    # An existing folder is left where it was.
    (tmp_path / "kept").mkdir()
    assert main([*argv, "--out", str(tmp_path / "kept")]) == 2
    assert (tmp_path / "kept").is_dir()
