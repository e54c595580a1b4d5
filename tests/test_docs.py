"""Every relative link in the README and the docs points to a file of the repository."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: The pages that describe the present; docs/history/ records commands as they ran on
#: their date (options renamed or removed since are in CHANGELOG.md).
PRESENT_PAGES = [p for p in PAGES if "history" not in p.relative_to(ROOT).parts]
LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    missing = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            continue
        path = (page.parent / target.split("#")[0]).resolve()
        if not path.exists():
            missing.append(target)
    assert not missing, f"{page.relative_to(ROOT)} links to missing files: {missing}"


def test_the_result_pages_are_there():
    assert {p.name for p in (ROOT / "docs" / "results").glob("*.md")} >= {
        "control.md", "identification.md", "rl.md"}


# --------------------------------------------------------------------------
# Documented commands and snippets run, so the documentation cannot drift
# --------------------------------------------------------------------------

FENCE = re.compile(r"```(\w*)\n(.*?)```", re.S)
INLINE = re.compile(r"`(spacecraft [^`]+)`")
#: Placeholders the docs use inside otherwise concrete command lines.
PLACEHOLDERS = {"F": "none", "S": "0"}


def _documented_commands() -> list[tuple[str, str]]:
    """(page, command) for every concrete ``spacecraft ...`` line of the README and the
    docs that describe the present: inline code and lines of fenced blocks (synopses
    with [...] or <...> excluded)."""
    found = []
    for page in PRESENT_PAGES:
        text = page.read_text()
        # inline code naming a command with arguments (a bare `spacecraft train` names it)
        candidates = [" ".join(m.split()) for m in INLINE.findall(text) if len(m.split()) > 2]
        for lang, body in FENCE.findall(text):
            if lang == "bash":            # a plain block is a synopsis, not a command
                candidates += [line.split("  #")[0].strip().removeprefix(".venv/bin/")
                               for line in body.splitlines()
                               if line.startswith(("spacecraft ", ".venv/bin/spacecraft "))]
        for command in candidates:
            if any(c in command for c in "[]<>") or command.endswith("..."):
                continue
            found.append((str(page.relative_to(ROOT)), command))
    return found


def _dry_parser():
    """The real parser with the checks that need files on disk (run directories,
    sweep files) relaxed to plain strings: the docs name outputs of runs not in git."""
    import argparse

    from spacecraft_lab.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command in sub.choices.values():
        for action in command._actions:
            if getattr(action.type, "__name__", "") in ("_run_directory", "_existing_file",
                                                              "_sweep_directory"):
                action.type = str
    return parser


def test_every_documented_command_line_parses():
    import shlex

    commands = _documented_commands()
    assert len(commands) > 15
    parser = _dry_parser()
    bad = []
    for page, command in commands:
        argv = [PLACEHOLDERS.get(tok, tok) for tok in shlex.split(command)[1:]]
        if argv in (["--help"], ["--version"]):
            continue
        try:
            parser.parse_args(argv)
        except SystemExit:
            bad.append(f"{page}: {command}")
    assert not bad, "documented commands the CLI rejects:\n" + "\n".join(bad)


def test_the_guides_synopsis_is_the_parsers():
    from spacecraft_lab.cli import synopsis

    text = (ROOT / "docs" / "guide.md").read_text()
    block = text[text.index("## Command line"):]
    shown = FENCE.search(block).group(2).rstrip("\n")
    assert shown == synopsis(), "regenerate with: python -c 'from spacecraft_lab.cli " \
        "import synopsis; print(synopsis())'"


def _snippets() -> list[tuple[str, str]]:
    return [(f"{page.relative_to(ROOT)}#{i}", body)
            for page in PAGES
            for i, (lang, body) in enumerate(FENCE.findall(page.read_text()))
            if lang == "python"]


@pytest.mark.parametrize(("where", "code"), _snippets(), ids=lambda v: v if "#" in v else "")
def test_python_snippets_run(where, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(code, where, "exec"), {"__name__": "__snippet__"})


def test_the_api_reference_builds_without_warnings(tmp_path):
    """`make docs`: pdoc over every package, numpydoc docstrings, warnings as errors, on the
    main install (the RL and cluster extras are not needed)."""
    import importlib
    import subprocess
    import sys

    pytest.importorskip("pdoc")
    make = (ROOT / "Makefile").read_text()
    command = re.search(r"^docs:.*?\n\t.*?\n\t\$\(BIN\)/python (.*?)(?<!\\)\n", make,
                        re.S | re.M).group(1).replace("\\\n", " ").split()
    command[command.index("build/api")] = str(tmp_path)
    # on the main install: the RL and cluster extras blocked, as if not installed
    assert command[:3] == ["-W", "error", "-m"] and command[3] == "pdoc"
    blocked = f"""
import runpy, sys

class Absent:
    names = {{"torch", "stable_baselines3", "sb3_contrib", "ray", "rl_zoo3", "tensorboard"}}

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in self.names:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked)", name=name)

sys.meta_path.insert(0, Absent())
sys.argv = ["pdoc", *{command[4:]!r}]
runpy.run_module("pdoc", run_name="__main__")
"""
    done = subprocess.run([sys.executable, "-W", "error", "-c", blocked], capture_output=True,
                          text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0 and not done.stderr.strip(), done.stderr[-3000:]
    # one page per package: its public API (``__all__``), numpydoc sections rendered
    page = (tmp_path / "controllers.html").read_text()
    assert "PhysicalFeatures" in page and "Parameters" in page
    # cross-references render as names, not as Sphinx's "~" shorthand
    for html in tmp_path.glob("*.html"):
        assert "<code>~" not in html.read_text(), html.name
    # the env's Gymnasium-style sections render as tables, not as one paragraph
    env_page = (tmp_path / "spacecraft_env.html").read_text()
    section = env_page[env_page.index('id="FlexibleSpacecraftEnv"'):]
    section = section[:section.index('id="FlexibleSpacecraftEnv.__init__"')]
    assert section.count("<table>") >= 6, "Action/Observation/Reward/... tables"
    # the landing page maps use cases to objects, and every link names a public object
    index = (tmp_path / "index.html").read_text()
    links = re.findall(r'href="(\w+)\.html#(\w+)"', index)
    assert len(links) >= 30
    for package, name in links:
        assert name in importlib.import_module(package).__all__, f"{package}.{name}"


# --------------------------------------------------------------------------
# The API reference: every public object says what it takes and what it gives
# --------------------------------------------------------------------------

#: The packages of the API reference (``make docs``), each read through its ``__all__``.
API_PACKAGES = ("spacecraft_conventions", "spacecraft_env", "identifiers", "controllers",
                "spacecraft_lab", "spacecraft_lab.sweeps")
SECTION = re.compile(r"^(\w[\w ]*)\n-{3,}\s*$", re.M)


def _sections(doc: str | None) -> set[str]:
    """The numpydoc section titles of a docstring (``Parameters``, ``Returns``, ...)."""
    return set(SECTION.findall(doc or ""))


def _public_objects():
    """(qualified name, object) of every class and function of the packages' ``__all__``,
    each object once (under the first package that exports it)."""
    import importlib
    import inspect

    seen = set()
    for package in API_PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if (inspect.isclass(obj) or inspect.isfunction(obj)) and id(obj) not in seen:
                seen.add(id(obj))
                yield f"{package}.{name}", obj


def _undocumented(obj) -> list[str]:
    """The sections ``obj`` lacks: ``Parameters`` if it takes arguments (for a class:
    Parameters or Attributes, in its docstring or ``__init__``'s), ``Returns`` (or
    ``Yields``) if a function returns something."""
    import inspect

    sections = _sections(inspect.getdoc(obj))
    if inspect.isclass(obj):
        init_doc = obj.__init__.__doc__ if "__init__" in vars(obj) else None
        sections |= _sections(inspect.cleandoc(init_doc) if init_doc else "")
        try:
            takes = bool(inspect.signature(obj).parameters)
        except (ValueError, TypeError):
            takes = False
    else:
        takes = bool(inspect.signature(obj).parameters)
    missing = []
    if takes and not sections & {"Parameters", "Attributes", "Other Parameters"}:
        missing.append("Parameters")
    if inspect.isfunction(obj) and _lacks_returns(obj, sections):
        missing.append("Returns")
    return missing


def _lacks_returns(func, sections: set[str]) -> bool:
    """Whether ``func`` returns something (its annotation) and ``sections`` of its
    docstring hold neither ``Returns`` nor ``Yields``."""
    import inspect

    returns = inspect.signature(func).return_annotation
    return (returns not in (None, "None", inspect.Signature.empty)
            and not sections & {"Returns", "Yields"})


def test_every_public_object_documents_its_parameters_and_returns():
    objects = list(_public_objects())
    assert len(objects) > 100
    offenders = [f"{name}: {missing}" for name, obj in objects
                 if (missing := _undocumented(obj))]
    assert not offenders, "public objects without the numpydoc sections:\n" + \
        "\n".join(offenders)


def _public_methods():
    """(qualified name, function) of every public method an exported class defines
    (properties aside), each once."""
    import inspect

    seen = set()
    for name, cls in _public_objects():
        if not inspect.isclass(cls):
            continue
        for attr, member in vars(cls).items():
            func = member.__func__ if isinstance(member, (classmethod, staticmethod)) \
                else member
            if attr.startswith("_") or not inspect.isfunction(func) or id(func) in seen:
                continue
            seen.add(id(func))
            yield f"{name}.{attr}", func


def test_every_public_method_says_what_it_returns():
    """A method that returns something has ``Returns`` (or ``Yields``) in its docstring,
    its own or the one it inherits (an override of a documented method, gymnasium's
    ``step`` and ``reset`` included, says nothing new)."""
    import inspect

    methods = list(_public_methods())
    assert len(methods) > 200
    offenders = []
    for name, func in methods:
        doc = inspect.getdoc(func) or ""
        if func.__doc__ is None and "Returns:" in doc:
            continue                     # gymnasium's (Google-style) docstring, inherited
        if _lacks_returns(func, _sections(doc)):
            offenders.append(name)
    assert not offenders, "public methods without Returns:\n" + "\n".join(offenders)


def test_entry_point_examples_run():
    """The ``Examples`` of the main entry points are doctests, and they pass."""
    import doctest

    from controllers import (
        AdaptiveLQG,
        IdentifiedModelFeatures,
        PhysicalFeatures,
        ProcessNoiseBank,
        Trajectory,
        closed_loop_identifier,
        compare,
        fast_identifier,
        run_episode,
        scheduled_identifier,
    )
    from identifiers import ClassicalRPBSID, ImprovedRPBSID, StateSpaceModel, default_identifier
    from spacecraft_env import FlexibleSpacecraftEnv, check_parameter
    from spacecraft_lab.score_cache import ScoreCache

    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner()
    failed, report = 0, []
    for obj in (FlexibleSpacecraftEnv, default_identifier, ImprovedRPBSID, ClassicalRPBSID,
                StateSpaceModel.modal, AdaptiveLQG, run_episode, compare, Trajectory,
                PhysicalFeatures, IdentifiedModelFeatures, check_parameter, ScoreCache,
                closed_loop_identifier, fast_identifier, scheduled_identifier,
                ProcessNoiseBank):
        tests = [t for t in finder.find(obj) if t.examples]
        assert tests, f"{obj.__qualname__} has no doctest examples"
        for test in tests:
            failed += runner.run(test, out=report.append).failed
    assert not failed, "".join(report)


def test_the_readme_is_a_front_page():
    """At most 150 lines, the two set-up commands on its first screen (24 lines)."""
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 150
    first_screen = "\n".join(lines[:24])
    assert "make demo" in first_screen and "make test" in first_screen
