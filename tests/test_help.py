"""Every sub-command has a description and every option a help text whose stated default is
argparse's real default (issue 26: a help that answers)."""

from __future__ import annotations

import argparse
import re

import pytest

from slamrel.cli import build_parser


def _commands(parser: argparse.ArgumentParser, prefix: str = "slamrel"):
    """(name, parser) of every sub-command, nested ones too."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f"{prefix} {name}", sub
                yield from _commands(sub, f"{prefix} {name}")


COMMANDS = list(_commands(build_parser()))
_NAMED_DEFAULT = re.compile(r"([\w.-]+) \(default[,)]")
_STATED = re.compile(r"\(default:? ([^)]*)\)|default:? ([^\s;,)]+)")


def _options(parser):
    for a in parser._actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        yield a


def _stated_default(action) -> str | None:
    """The default the help text states, %(default)s filled in as argparse does."""
    text = (action.help or "") % {
        "default": action.default,
        "prog": "x",
        "dest": action.dest,
        "choices": action.choices,
        "metavar": action.metavar,
        "type": action.type,
        "required": action.required,
    }
    m = _STATED.search(text)
    if m is not None:
        return (m.group(1) or m.group(2)).strip()
    m = _NAMED_DEFAULT.search(text)  # "sqrt-information (default, ...)": the word before
    return None if m is None else m.group(1)


@pytest.mark.parametrize(("name", "parser"), COMMANDS, ids=[c[0] for c in COMMANDS])
def test_every_command_and_option_has_help(name, parser):
    assert parser.description, f"{name}: no description"
    assert "fit_noise" not in (parser.description or "")  # no Python function as the answer
    missing = [
        a.option_strings[0] if a.option_strings else a.dest for a in _options(parser) if not a.help
    ]
    assert not missing, f"{name}: options without help: {missing}"


def _same(stated: str, real) -> bool:
    s = stated.strip("'\" ;,")
    if real is None:
        return False
    if isinstance(real, bool):
        return False
    if isinstance(real, (int, float)):
        try:
            return float(s.rstrip("smx°%")) == float(real)
        except ValueError:
            return False
    if isinstance(real, (list, tuple)):
        return s.replace(" ", "") in (",".join(map(str, real)), str(list(real)).replace(" ", ""))
    return s == str(real)


@pytest.mark.parametrize(("name", "parser"), COMMANDS, ids=[c[0] for c in COMMANDS])
def test_stated_defaults_are_the_real_ones(name, parser):
    wrong = []
    for a in _options(parser):
        stated = _stated_default(a)
        if stated is None or a.default is None or isinstance(a.default, bool):
            continue  # "default: none/recognised/all poses": a meaning, not a value
        first = stated.split()[0].strip("'\" ;,")
        if isinstance(a.default, (list, tuple)) and first.split(",")[0] not in map(str, a.default):
            continue  # "the paper's four": words, not a value
        if not _same(first, a.default):
            wrong.append(
                (a.option_strings or [a.dest])[0] + f": states {stated!r}, is {a.default!r}"
            )
    assert not wrong, f"{name}: " + "; ".join(wrong)


@pytest.mark.parametrize(("name", "parser"), COMMANDS, ids=[c[0] for c in COMMANDS])
def test_valued_options_state_their_default(name, parser):
    """An option with a real (non-None, non-flag) default says it in its help."""
    silent = []
    for a in _options(parser):
        if not a.option_strings or a.default is None or isinstance(a.default, bool):
            continue
        if a.nargs == 0 or a.default == argparse.SUPPRESS:
            continue
        if _stated_default(a) is None:
            silent.append(a.option_strings[0])
    assert not silent, f"{name}: options with a default their help does not state: {silent}"


def test_the_checker_catches_a_wrong_and_a_silent_default():
    p = argparse.ArgumentParser(description="d")
    p.add_argument("--a", type=float, default=0.5, help="a thing (default: 0.1)")
    p.add_argument("--b", type=int, default=3, help="b thing")
    p.add_argument("--c", default="x", help="c thing (default: %(default)s)")
    with pytest.raises(AssertionError, match=r"--a: states '0.1', is 0.5"):
        test_stated_defaults_are_the_real_ones("t", p)
    with pytest.raises(AssertionError, match=r"\['--a'\]|\['--b'\]"):
        test_valued_options_state_their_default("t", p)


def test_noise_help_states_the_noise_types():
    from slamrel.constants import NOISE_HELP
    from slamrel.simulation.worlds import NOISE_TYPES

    for name, nt in NOISE_TYPES.items():
        part = NOISE_HELP.split(f"{name}: ")[1].split(";")[0]
        numbers = [float(x) for x in re.findall(r"\d+\.\d+", part)]
        assert numbers == [nt.sigma_dx, nt.sigma_dtheta, nt.sigma_observation], name
        assert nt.sigma_dx == nt.sigma_dy


def test_run_help_names_its_input_one_way():
    """Issue 38: `run --help` called its input a "SLAM result bundle" and a "log bundle"."""
    text = dict(_commands(build_parser()))["slamrel run"].format_help()
    flat = " ".join(text.split())  # argparse wraps lines anywhere
    assert "log bundle" not in flat
    assert flat.count("SLAM result bundle directory") >= 2  # the description and SOURCE
