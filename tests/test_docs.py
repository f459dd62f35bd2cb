"""The documentation is split by reader: one current page per topic, linked from the README,
with working links and commands, and no dated history of how figures changed."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

TOPIC_PAGES = [
    "docs/environment.md",
    "docs/navigation.md",
    "docs/integrity.md",
    "docs/training.md",
    "docs/evaluation.md",
    "docs/reproduction/README.md",
    "docs/performance.md",
]
"""One page per reader topic."""

PAGES = ["README.md", "CONTRIBUTING.md", *TOPIC_PAGES]
"""Pages written by hand (generated reports such as docs/reproduction/report.md excluded)."""

DATED_HISTORY = [
    r"\bthis session\b",
    r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth) session\b",
    r"\bmeasured on (today|the final|the current|this)\b",
    r"\bon the final code\b",
    r"\b(a|the) (second|third|fourth|fifth) (try|attempt|confirmatory)\b",
    r"\b(19|20)\d\d-\d\d-\d\d\b",
    r"\bearlier runs? gave\b",
    r"\bbefore this (round|work|change|session)\b",
    r"\b(first|second|third|fourth) round\b",
    r"\bin the (morning|evening|afternoon)\b",
    r"\b(today|yesterday)\b",
    r"\bthis page quoted before\b",
]
"""Phrases that date a figure by when it was measured instead of tying it to its command."""


def _text(page: str) -> str:
    return (ROOT / page).read_text()


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return {_slug(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


@pytest.mark.parametrize("page", TOPIC_PAGES)
def test_every_topic_page_exists_and_the_readme_links_it(page):
    assert (ROOT / page).is_file(), page
    assert _text(page).startswith("# "), page
    readme = _text("README.md")
    link = page.removesuffix("README.md") if page.endswith("/README.md") else page
    assert f"]({link}" in readme, page


@pytest.mark.parametrize("page", PAGES)
def test_pages_carry_no_dated_history(page):
    text = _text(page)
    for pattern in DATED_HISTORY:
        hit = re.search(pattern, text, re.I)
        assert hit is None, f"{page}: {hit.group(0)!r} dates a figure; name its command instead"


@pytest.mark.parametrize("page", PAGES)
def test_relative_links_and_anchors_resolve(page):
    """Every relative link of the page names a file or folder of the repository, and every
    ``#anchor`` a heading of its target."""
    base = (ROOT / page).parent
    text = re.sub(r"```.*?```", "", _text(page), flags=re.S)
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert links, page
    for link in links:
        if re.match(r"[a-z]+://", link):
            continue
        target, _, anchor = link.partition("#")
        path = (base / target).resolve() if target else ROOT / page
        assert path.exists(), f"{page}: broken link {link}"
        if anchor:
            assert path.is_file() and anchor in _anchors(path), f"{page}: no anchor {link}"


@pytest.mark.parametrize("page", PAGES)
def test_scripts_the_pages_run_exist(page):
    """``python PATH.py`` commands name scripts of the repository."""
    for script in re.findall(r"\bpython3? ((?:[\w.-]+/)*[\w.-]+\.py)\b", _text(page)):
        assert (ROOT / script).is_file(), f"{page}: no script {script}"


def test_pages_import_the_installed_names():
    """Code in the pages imports ``coopnav_env.agents`` etc., never the deprecated names."""
    old = re.compile(r"^\s*(from|import) (agents|training|reproduction)\b", re.M)
    for page in PAGES:
        for block in re.findall(r"```python\n(.*?)```", _text(page), re.S):
            assert not old.search(block), page


def _unreleased() -> str:
    text = _text("CHANGELOG.md")
    return text.split("\n## [Unreleased]\n", 1)[1].split("\n## [", 1)[0]


def test_changelog_unreleased_lists_changes_not_results():
    """The changelog says what changed for users; results (intervals, study figures, study
    folders) live in studies/."""
    text = _unreleased()
    interval = r"\[[+-]?\d+(\.\d+)?, ?[+-]?\d+(\.\d+)?\]"
    assert re.search(interval, text) is None, "a confidence interval in the changelog"
    assert re.search(r"\d+(\.\d+)? m\b", text) is None, "a figure in metres in the changelog"
    assert "docs/marl" not in text
    assert len(re.findall(r"^### (Added|Changed|Deprecated|Removed|Fixed)$", text, re.M)) == len(
        set(re.findall(r"^### (.+)$", text, re.M))
    ), "a heading repeated in [Unreleased]"


def test_changelog_announces_the_namespace_and_the_deprecation():
    text = _unreleased()
    deprecated = text.split("### Deprecated\n", 1)[1].split("\n### ", 1)[0]
    for old in ("agents", "training", "reproduction"):
        assert f"`coopnav_env.{old}`" in text, old
        assert f"`{old}`" in deprecated, old
    assert "DeprecationWarning" in deprecated
