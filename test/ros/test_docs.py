"""The docs stay true to the code: generated parts equal what the code gives now, every link
resolves, and the front page stays one screen's worth."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
from transparency_ros.ros import docgen

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_generated_tables_and_config_files_equal_the_code() -> None:
    """Parameter tables (from each node's ParamSpec rows), config/<node>.yaml and the
    subcommand table; `make docs` regenerates them."""
    assert [p.relative_to(ROOT).as_posix() for p in docgen.stale()] == []


def test_every_node_parameter_is_on_its_page() -> None:
    for node, specs in docgen._node_tables().items():
        page = (ROOT / "docs" / f"{node}.md").read_text()
        assert [s.name for s in specs() if f"| `{s.name}` |" not in page] == [], node


def test_a_stale_table_is_found() -> None:
    """The check can fail: a page whose table lost a row is reported."""
    page = ROOT / "docs" / "contact_estimator.md"
    text = page.read_text()
    damaged = text.replace("| `queue_depth` |", "| `queue_depth_renamed` |")
    generated = docgen.blocks()[page]
    assert damaged != text
    assert docgen.render(damaged, page, generated) == text  # differs from the page: stale


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page: Path) -> None:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    missing = []
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target:
            continue
        if not (page.parent / target).exists():
            missing.append(target)
    assert missing == []


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but - and _ dropped, spaces -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_link_to_a_section_names_a_heading_of_its_page(page: Path) -> None:
    """A README row that points into a page's section (page.md#section) lands on it."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    missing = []
    for target, anchor in re.findall(r"\]\(([^)#\s]*)#([^)\s]+)\)", text):
        linked = page.parent / target if target else page
        if linked.suffix != ".md" or not linked.exists():
            continue
        body = re.sub(r"```.*?```", "", linked.read_text(), flags=re.S)
        if anchor not in {_slug(h) for h in re.findall(r"^#+ (.*)$", body, flags=re.M)}:
            missing.append(f"{target}#{anchor}")
    assert missing == []


def test_the_front_page_is_short_and_links_every_page() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    unlinked = [p.name for p in PAGES[1:] if f"(docs/{p.name})" not in readme]
    assert unlinked == []
