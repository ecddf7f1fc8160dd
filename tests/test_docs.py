"""The README leads and the docs hold the rest: it stays short, links every page, and no link is broken."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _links(md: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(md.read_text()) if not m.group(1).startswith(("http://", "https://", "#"))]


def test_readme_is_short_and_links_every_page():
    readme = ROOT / "README.md"
    assert len(readme.read_text().splitlines()) <= 300
    linked = {(ROOT / link.split("#")[0]).resolve() for link in _links(readme)}
    pages = list((ROOT / "docs").glob("*.md")) + list((ROOT / "planners").glob("*/README.md"))
    missing = [str(p.relative_to(ROOT)) for p in pages if p.resolve() not in linked]
    assert not missing, f"pages the README does not link: {missing}"


def test_relative_links_resolve():
    docs = [ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *(ROOT / "planners").glob("*/*.md"),
            ROOT / "leaderboard" / "COMMANDS.md"]
    broken = []
    for md in docs:
        for link in _links(md):
            target = (md.parent / link.split("#")[0]).resolve()
            if not target.exists():
                broken.append(f"{md.relative_to(ROOT)}: {link}")
    assert not broken, broken


def test_readme_quick_start_is_what_ci_runs():
    """`.ci/run` runs the README's test command; the two must not drift apart."""
    readme = (ROOT / "README.md").read_text()
    assert "pip install -e '.[test]' && python -m pytest\n" in readme
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install --quiet -e '.[test]'" in ci and ci.rstrip().endswith("python -m pytest")


def _documented_commands() -> dict[str, set[str]]:
    """docs/commands.md's table: command name → the options its first cell shows (every form of it)."""
    text = (ROOT / "docs" / "commands.md").read_text()
    out: dict[str, set[str]] = {}
    for row in text.splitlines():
        if not row.startswith("| `earthbench "):
            continue
        first = re.split(r"(?<!\\)\|", row)[1]
        for form in re.findall(r"`earthbench ([^`]+)`", first):
            out.setdefault(form.split()[0], set()).update(re.findall(r"(?<![\w-])(--?[a-z][a-z-]*)", form))
    return out


def _parser_commands() -> dict[str, list[list[str]]]:
    """The command line's sub-commands → each option's spellings (without --help)."""
    import argparse

    from earthbench.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {name: [a.option_strings for a in p._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]
            for name, p in sub.choices.items()}


def test_commands_page_documents_every_command_and_option_and_nothing_else():
    documented, actual = _documented_commands(), _parser_commands()
    assert sorted(documented) == sorted(actual), "docs/commands.md's commands differ from the command line's"
    missing = [f"{c} {spellings[-1]}" for c, opts in actual.items() for spellings in opts
               if not set(spellings) & documented[c]]
    assert not missing, f"options docs/commands.md leaves out: {missing}"
    known = {c: {s for spellings in opts for s in spellings} for c, opts in actual.items()}
    gone = [f"{c} {o}" for c, opts in documented.items() for o in opts if o not in known[c]]
    assert not gone, f"options docs/commands.md names that the command does not take: {gone}"


def _board(name: str = "") -> pd.DataFrame:
    """A published board's suite-scope rows of each planner's latest version (``leaderboard/NAME/summary.csv``)."""
    d = pd.read_csv(ROOT / "leaderboard" / name / "summary.csv", dtype={"planner_version": str})
    return d[(d["scope"] == "suite") & d["latest"].astype(bool)]


def _sentence(text: str, start: str) -> str:
    """The paragraph of ``text`` from ``start`` on (to its blank line): the claim a test reads."""
    assert start in text, f"the sentence starting {start!r} is gone: move its check with it"
    return text[text.index(start):].split("\n\n")[0]


def test_readme_solve_medians_are_the_boards():
    """The README's solve-time medians are the `standard` board's, to the digits written."""
    claim = _sentence((ROOT / "README.md").read_text(), "times — on the published `standard` board")
    quoted = {p: v for v, p in re.findall(r"(\d+(?:\.\d+)?) s for\s+`([a-z-]+)`", claim)}
    board = _board().query("suite == 'standard'").set_index("planner")["solve_time_median"]
    assert sorted(quoted) == sorted(board.index), "the README should quote every planner of the board"
    for planner, text in quoted.items():
        digits = len(text.split(".")[1]) if "." in text else 0
        assert float(text) == round(float(board[planner]), digits), (
            f"README says {text} s for {planner}; leaderboard/summary.csv has {board[planner]:.3f} s")


def test_readme_names_the_boards_planners_versions_and_size():
    readme = (ROOT / "README.md").read_text()
    standard = _board().query("suite == 'standard'")
    claim = " ".join(_sentence(readme, "- [backhoe](leaderboard/README.md)").split())
    m = re.search(r"\(([^()]*) on the (\d+) scenarios of `standard`\)", claim)
    assert m, claim
    assert sorted(re.split(r", | and ", m.group(1))) == sorted(standard["planner"]), m.group(1)
    assert int(m.group(2)) == int(standard["of"].max())
    remade = " ".join(_sentence(readme, "Which versions each holds").split())
    for board, planner in (("closed-loop", "stl-tamp"), ("scale", "stl-tamp")):
        version = _board(board).query("planner == @planner")["planner_version"].max()
        assert f"the {board} board with {planner + ' ' if board == 'closed-loop' else ''}{version}" in remade, (board, version)


def test_closed_loop_page_names_rows_the_board_has():
    """The closed-loop page's example rows (`NAME VERSION closed-loop` and `NAME VERSION`) are on the published board."""
    page = (ROOT / "docs" / "closed-loop.md").read_text()
    board = (ROOT / "leaderboard" / "closed-loop" / "README.md").read_text()
    named = re.findall(r"`([a-z][a-z-]* \d+(?:\.\d+)+(?: closed-loop)?)`", page)
    assert len(named) >= 2
    for label in named:
        assert f"solve times of {label}:" in board, f"docs/closed-loop.md names `{label}`, which the closed-loop board lacks"


def test_readme_preparation_time_is_the_boards():
    """The README's stl-tamp preparation time is the `standard` board's "Prepare s", to the second."""
    claim = " ".join(_sentence((ROOT / "README.md").read_text(), "On a 2-core AMD EPYC").split())
    m = re.search(r"prepares stl-tamp, once \(it took (\d+) s for the published `standard` board", claim)
    assert m, claim
    board = _board().query("suite == 'standard' and planner == 'stl-tamp'")["prepare_max"]
    assert int(m.group(1)) == round(float(board.iloc[0]))
