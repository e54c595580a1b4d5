"""One name per thing: every choice the command line accepts is in docs/glossary.md, with one
meaning, and the glossary holds nothing the command line no longer accepts."""

from __future__ import annotations

import argparse
import re
from collections import Counter
from pathlib import Path

import pytest

from spacecraft_lab.cli import build_parser
from spacecraft_lab.control import CONTROLLER_KEYS

GLOSSARY = Path(__file__).resolve().parents[1] / "docs" / "glossary.md"
#: (sub-command, option) -> the glossary's section that defines its choices.
SECTIONS = {
    ("demo", "--scenario"): "Scenarios", ("identify", "--scenario"): "Scenarios",
    ("control", "--scenario"): "Scenarios", ("train", "--scenario"): "Scenarios",
    ("control", "--task"): "Tasks", ("identify", "--methods"): "Identifiers",
    ("identify", "--preset"): "Presets", ("control", "--controllers"): "Controllers",
    ("train", "--features"): "Agent observations and bases", ("train", "--reward"): "Rewards",
    ("train", "--algo"): "Algorithms", ("sweep", "--backend"): "Sweep backends",
}


def _glossary() -> dict[str, list[tuple[str, list[str]]]]:
    """Section title -> its rows, each (name, the other cells)."""
    sections: dict[str, list[tuple[str, list[str]]]] = {}
    title = None
    for line in GLOSSARY.read_text().splitlines():
        if line.startswith("## "):
            title = line[3:].split(" (")[0]
            sections[title] = []
        elif title and (row := re.match(r"^\| `([^`]+)` \|(.*)\|$", line)):
            sections[title].append((row[1], [c.strip() for c in row[2].split("|")]))
    return sections


def _choices() -> dict[tuple[str, str], list[str]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {(command, action.option_strings[0]): [str(c) for c in action.choices]
            for command, p in sub.choices.items() for action in p._actions
            if action.choices is not None and action.option_strings}


def test_every_option_with_choices_has_a_glossary_section():
    assert set(_choices()) == set(SECTIONS), "map a new option to its glossary section"


@pytest.mark.parametrize("option", sorted(SECTIONS), ids=" ".join)
def test_every_choice_is_in_the_glossary(option):
    names = {name for name, _ in _glossary()[SECTIONS[option]]}
    missing = set(_choices()[option]) - names
    assert not missing, f"{option}: {sorted(missing)} not in docs/glossary.md"


def test_the_glossary_holds_nothing_stale_and_no_name_twice():
    glossary, choices = _glossary(), _choices()
    for title, rows in glossary.items():
        accepted = {c for option, section in SECTIONS.items() if section == title
                    for c in choices[option]}
        stale = {name for name, _ in rows} - accepted
        assert not stale, f"{title}: {sorted(stale)} no longer accepted"
    twice = [n for n, k in Counter(n for rows in glossary.values() for n, _ in rows).items()
             if k > 1]
    assert twice == []
    assert "default" not in {n for rows in glossary.values() for n, _ in rows}


def test_each_controller_is_shown_under_one_name_and_the_glossary_says_which():
    shown = list(CONTROLLER_KEYS.values())
    assert len(set(shown)) == len(shown)
    rows = dict(_glossary()["Controllers"])
    assert {key: rows[key][0] for key in CONTROLLER_KEYS} == CONTROLLER_KEYS
