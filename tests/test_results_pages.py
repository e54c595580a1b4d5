"""The results pages are what their commands print: every table of docs/results/control.md
and rl.md sits in a block written from the data its command kept (`make results-short`
renders them again; `make results` runs the commands first)."""

from __future__ import annotations

import json

import pytest

from spacecraft_lab import results_pages as rp


def test_every_block_is_what_its_data_render():
    """The short mode of ``make results``: each block rendered again from
    docs/results/data equals the page (a hand edit, or data kept without the page written,
    fails here)."""
    assert rp.check() == []


@pytest.mark.parametrize("page", rp.WHOLLY_WRITTEN)
def test_every_table_of_a_results_page_is_in_a_block_with_its_command_and_date(page):
    text = (rp.ROOT / page).read_text()
    head, *chunks = text.split(rp.BEGIN + "\n")
    outside = head + "".join(chunk.split(rp.END, 1)[1] for chunk in chunks)
    assert "```text" not in outside and "|---" not in outside
    assert len(rp.blocks(page)) == len(chunks) >= 3


@pytest.mark.parametrize("page", rp.PAGES)
def test_every_block_names_its_data_and_its_date(page):
    printed = json.loads((rp.ROOT / rp.PRINTED).read_text())
    for block in rp.blocks(page):
        assert block.commands and (rp.ROOT / block.data).exists()
        assert f"Printed {printed[str(block.data)]} by the command above." in block.body


def test_blocks_are_parsed_and_bad_ones_refused():
    fence = "```bash\nspacecraft control --seeds 3 --out results/ceiling/x\n```\n"
    text = f"intro\n{rp.BEGIN}\n{fence}\nold table\n{rp.END}\nafter\n"
    (block,) = rp.blocks("page.md", text)
    assert block.kind == "control" and block.body == "\nold table\n"
    assert str(block.data) == "docs/results/data/control/ceiling-x.json"
    with pytest.raises(ValueError, match="not closed"):
        rp.blocks("page.md", f"{rp.BEGIN}\n{fence}")
    with pytest.raises(ValueError, match="bash fence"):
        rp.blocks("page.md", f"{rp.BEGIN}\ntable\n{rp.END}\n")
    odd = rp.Block("page.md", ("ls results",), "")
    with pytest.raises(ValueError, match="last command must be"):
        _ = odd.kind
    outside = rp.Block("page.md", ("python benchmarks/b.py --markdown results/x.json",), "")
    with pytest.raises(ValueError, match="docs/results/data"):
        _ = outside.data
    with pytest.raises(FileNotFoundError, match="make results"):
        rp.render(rp.Block("page.md", ("spacecraft control --out results/none/here",), ""))


def test_the_readmes_headline_table_is_the_control_pages_first_block():
    """The README's table of the main comparison shows, per controller it lists, the cells
    `spacecraft control --scenario paddle_rotation --seeds 3` printed on the results page
    (from the same kept data)."""
    import re

    from spacecraft_lab.reporting import control_brief

    (block,) = [b for b in rp.blocks("docs/results/control.md")
                if b.commands == ("spacecraft control --scenario paddle_rotation --seeds 3 "
                                  "--out results/ceiling/paddle_rotation",)]
    brief = control_brief(json.loads((rp.ROOT / block.data).read_text())["controllers"])
    printed = {cells[0]: cells[1:7] for cells in
               (re.split(r"\s{2,}", line.strip()) for line in brief.splitlines()[1:])}
    readme = (rp.ROOT / "README.md").read_text()
    assert "`spacecraft control --scenario paddle_rotation --seeds 3`" in readme
    rows = [line.strip("|").split("|") for line in readme.splitlines()
            if line.startswith("| ") and "cost, whole episode" not in line
            and line.split("|")[1].strip() in printed]
    assert len(rows) >= 6
    for name, *cells in ([c.strip() for c in row] for row in rows):
        assert cells == printed[name], name
