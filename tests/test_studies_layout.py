"""The library stays apart from the studies (issue 33).

Checked by reading the source (``ast``, ``tokenize``, regular expressions), nothing is imported:

* no installed module (``coopnav_env/``, ``agents/``, ``training/``, ``reproduction/``) imports
  from ``studies`` or names a path into it in its code (it is not installed);
* no docstring or comment of the installed code quotes a study result: no figure with its
  confidence interval (``-0.22 m [-0.36, -0.07]``), no count of episodes with the figure
  measured on them, no path to a study's results beside a figure, and no ``docs/marl`` (the
  old home of the results); docstrings say what the code does and link the study instead;
* ``studies/`` is not a package of the wheel, and every study folder has a README.md that
  answers first: the sections question, answer, how to regenerate, set-up (in that order), at
  most 150 lines, an answer of at most about 30 lines of prose beside its tables; the record
  in the order it was done lives in a LOG.md beside it, which the README links; the scripts
  that either page runs exist; every study is listed with a headline number in
  ``studies/README.md``;
* ``benchmarks/`` holds speed measurements only (``bench_*.py``).
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
INSTALLED = ("coopnav_env", "agents", "training", "reproduction")
STUDY_SECTIONS = ("question", "answer", "how to regenerate", "set-up")
MAX_README_LINES = 150
MAX_ANSWER_PROSE_LINES = 30
"""Non-blank lines of a study's Answer outside its tables."""

_NUMBER = r"[+-]?\d+(?:[.,]\d+)*"
_INTERVAL = re.compile(rf"{_NUMBER}\s*(?:m|%|s)?\s*\[\s*{_NUMBER}\s*,\s*{_NUMBER}\s*\]")
"""A figure followed by its interval: ``-0.22 m [-0.36, -0.07]``, ``0.12 [0.04, 0.19]``."""
_EPISODE_COUNT = re.compile(
    r"\b(?:(?:on|over|in)\s+(?:the\s+)?(?:first\s+)?\d[\d,]*|\d+\s+of\s+\d[\d,]*)"
    r"\s+(?:[\w'-]+\s+){0,3}episodes\b",
    re.IGNORECASE,
)
"""A count of flown episodes: ``on 300 such episodes``, ``19 of 20 held-out episodes``."""
_MEASURED = re.compile(r"\b\d+\.\d+\s*m\b(?![/\w])|\b\d+(?:\.\d+)?\s*%|\b\d+\s+of\s+\d+\b")
"""A measured figure: metres with decimals, a percentage, or ``k of n``."""
_RESULTS_PATH = re.compile(r"\bstudies/[\w./-]+")
_RANKING = re.compile(r"\bbest (?:heuristic|policy)\b[^.;]*\bstud(?:y|ies)\b", re.IGNORECASE)
"""A ranking the studies found: ``the best heuristic of the learning study``."""
_OLD_RESULTS = re.compile(r"docs/marl")


def _texts(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of every docstring, other string statement and comment of ``source``."""
    found = [
        (node.lineno, node.value.value)
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    ]
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            found.append((tok.start[0], tok.string))
    return found


def _sentences(text: str) -> list[str]:
    return re.split(r"(?<=[.;:])\s+(?=[A-Z(`*])", " ".join(text.split()))


def result_quotes(source: str) -> list[tuple[int, str]]:
    """``(line, sentence)`` for every sentence of ``source``'s docstrings and comments that quotes
    a study result (see the module docstring)."""
    found = []
    for line, text in _texts(source):
        for s in _sentences(text):
            if (
                _OLD_RESULTS.search(s)
                or _INTERVAL.search(s)
                or _RANKING.search(s)
                or (_EPISODE_COUNT.search(s) and _MEASURED.search(s))
                or (_RESULTS_PATH.search(s) and _MEASURED.search(s))
            ):
                found.append((line, s))
    return found


def studies_imports(source: str) -> list[tuple[int, str]]:
    """``(line, what)`` for every import of ``studies`` in ``source`` and every path into
    ``studies/`` in its code (string constants that are not docstrings)."""
    tree = ast.parse(source)
    docstrings = {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [
                (node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "studies"
            ]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            if node.module.split(".")[0] == "studies":
                found.append((node.lineno, node.module))
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings
            and re.search(r"(?:^|[\s\"'/])studies(?:/|\.\w)", node.value)
        ):
            found.append((node.lineno, node.value))
    return found


def _installed_files(suffixes: tuple[str, ...] = (".py",)) -> list[Path]:
    return sorted(
        p
        for d in INSTALLED
        for p in (ROOT / d).rglob("*")
        if p.suffix in suffixes and "__pycache__" not in p.parts and p.is_file()
    )


def _study_folders() -> list[Path]:
    """The folders under ``studies/`` that hold a file (git keeps no empty folder)."""
    return sorted(
        p
        for p in (ROOT / "studies").iterdir()
        if p.is_dir()
        and not p.name.startswith((".", "_"))
        and any(f.is_file() for f in p.rglob("*") if "__pycache__" not in f.parts)
    )


def test_no_installed_module_imports_from_studies():
    found = [
        f"{p.relative_to(ROOT)}:{line} {what}"
        for p in _installed_files()
        for line, what in studies_imports(p.read_text())
    ]
    assert found == []


def _quotes(files: list[Path]) -> list[str]:
    return [
        f"{p.relative_to(ROOT)}:{line}: {sentence}"
        for p in files
        for line, sentence in result_quotes(p.read_text())
    ]


def test_no_library_docstring_quotes_a_study_result():
    assert _quotes(_installed_files()) == []


def test_no_installed_data_file_points_at_the_old_results():
    found = [
        f"{p.relative_to(ROOT)}:{n}"
        for p in _installed_files((".yaml", ".yml", ".json", ".md", ".txt"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if _OLD_RESULTS.search(line)
    ]
    assert found == []


def test_the_checks_can_fail():
    """The checkers see what they are meant to see (on made-up modules)."""
    quoting = (
        '"""A column.\n\nOn the 1000 fresh episodes of the second study it flies at 3.34 m mean\n'
        "error (paired -0.22 m [-0.36, -0.07]).\n\nParameters\n----------\nx : float\n"
        '    Offset [m], in [0.0, 1.0].\n"""\n'
        "def f():\n"
        '    """On 300 such episodes it crashes in 2 % (``wide``: 15 %)."""\n'
        "    # studies/route_choice/results/gate8 has it at 2.10 m\n"
        "    x = 1  # see docs/marl/README.md\n"
        '    """It reaches the goal about as often (19 of 20 held-out episodes)."""\n'
        '    """The 45 m column: the best heuristic of the learning study."""\n'
    )
    assert sorted(line for line, _ in result_quotes(quoting)) == [1, 12, 13, 14, 15, 16]
    clean = (
        '"""A column that flies 40 held-out episodes by default (``--episodes``), 0.5 m below\n'
        "the ceiling, with a 95 % interval over episodes; bounds in [0.0, 1.0]. The study that\n"
        'chose it: ``studies/learning_in_default_setting``.\n"""\n'
        "# the paper's Table 2: 57.53 % at N = 5\n"
    )
    assert result_quotes(clean) == []
    imports = (
        "import studies.route_choice\nfrom studies import x\nfrom .studies import y\n"
        "import studiesx\n"
        'P = "studies/split_choice/results"\n'
        'def g():\n    """See ``studies/split_choice``."""\n'
    )
    assert studies_imports(imports) == [
        (1, "studies.route_choice"),
        (2, "studies"),
        (5, "studies/split_choice/results"),
    ]


def test_studies_are_not_installed():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    packages = data["tool"]["setuptools"]["packages"]
    assert not [p for p in packages if p.split(".")[0] == "studies" or ".studies" in p]
    assert "studies" not in data["tool"]["setuptools"].get("package-dir", {}).values()
    assert "studies" in data["tool"]["pytest"]["ini_options"]["testpaths"]


def unfenced_lines(text: str) -> list[str]:
    """The lines of a Markdown page outside its code blocks (the fences left out too)."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced:
            out.append(line)
    return out


def readme_sections(text: str) -> list[str]:
    """The level-2 headings of a Markdown page, lower case, in order (code blocks skipped)."""
    return [x[3:].strip().lower() for x in unfenced_lines(text) if x.startswith("## ")]


def readme_section(text: str, name: str) -> str:
    """The body of the level-2 section ``name`` (lower case) of a Markdown page, up to the next
    level-2 heading (headings inside code blocks do not count); ``""`` if there is none."""
    body, inside, fenced = [], False, False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        if not fenced and line.startswith("## "):
            inside = line[3:].strip().lower() == name
            continue
        if inside:
            body.append(line)
    return "\n".join(body)


def answer_prose_lines(text: str) -> int:
    """Non-blank lines of the page's Answer that are not table rows."""
    lines = readme_section(text, "answer").splitlines()
    return sum(1 for x in lines if x.strip() and not x.lstrip().startswith("|"))


def page_scripts(text: str) -> list[str]:
    """The ``PATH.py`` of every ``python PATH.py`` command of a page."""
    return re.findall(r"\bpython3? ((?:[\w.-]+/)*[\w.-]+\.py)\b", text)


def _study_pages(folder: Path) -> list[Path]:
    return [p for p in (folder / "README.md", folder / "LOG.md") if p.is_file()]


def test_every_study_has_a_readme_that_answers_first():
    folders = _study_folders()
    assert len(folders) >= 5
    for folder in folders:
        readme = folder / "README.md"
        assert readme.is_file(), folder
        text = readme.read_text()
        assert readme_sections(text) == list(STUDY_SECTIONS), (folder.name, readme_sections(text))
        n = len(text.splitlines())
        assert n <= MAX_README_LINES, (
            f"{folder.name}/README.md: {n} lines; move the record to LOG.md"
        )
        prose = answer_prose_lines(text)
        assert prose <= MAX_ANSWER_PROSE_LINES, f"{folder.name}: an Answer of {prose} lines"
        assert readme_section(text, "how to regenerate").count("```") >= 2, folder.name


def test_every_study_log_is_linked_from_its_readme():
    logs = [folder for folder in _study_folders() if (folder / "LOG.md").is_file()]
    assert logs
    for folder in logs:
        assert "](LOG.md)" in (folder / "README.md").read_text(), folder.name
        assert (folder / "LOG.md").read_text().startswith("# "), folder.name


def test_the_scripts_the_study_pages_run_exist():
    """``python PATH.py`` in a study's README or LOG.md names a script of the repository (or of
    the study's folder, for a path relative to it)."""
    missing = [
        f"{page.relative_to(ROOT)}: {script}"
        for folder in _study_folders()
        for page in _study_pages(folder)
        for script in page_scripts(page.read_text())
        if not (ROOT / script).is_file() and not (folder / script).is_file()
    ]
    assert missing == []


def _slugs(path: Path) -> set[str]:
    """GitHub's anchors of the headings of a Markdown page (code blocks skipped)."""
    heads = [
        m.group(1) for x in unfenced_lines(path.read_text()) if (m := re.match(r"#{1,6} (.+)$", x))
    ]
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in heads}


def test_the_links_of_the_study_pages_resolve():
    """Every relative link of a study's README and LOG.md, and of the index, names a file or
    folder of the repository, and every ``#anchor`` a heading of its target."""
    pages = [ROOT / "studies" / "README.md"]
    pages += [page for folder in _study_folders() for page in _study_pages(folder)]
    broken = []
    for page in pages:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
        for link in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+://", link):
                continue
            target, _, anchor = link.partition("#")
            path = (page.parent / target).resolve() if target else page
            if not path.exists() or (anchor and (not path.is_file() or anchor not in _slugs(path))):
                broken.append(f"{page.relative_to(ROOT)}: {link}")
    assert broken == []


def test_the_index_lists_every_study_with_a_number():
    index = (ROOT / "studies" / "README.md").read_text()
    for folder in _study_folders():
        lines = [x for x in index.splitlines() if f"]({folder.name}/" in x]
        assert len(lines) == 1, folder.name
        assert re.search(r"\d+(?:\.\d+)?\s*(?:m|%)", lines[0]), lines[0]


def test_readme_sections_are_checked():
    good = "# T\n\n## Question\n\n## Set-up\n```\n## not a heading\n```\n## Commands\n"
    assert readme_sections(good) == ["question", "set-up", "commands"]
    page = (
        "# T\n\n## Question\n\nQ?\n\n## Answer\n\nNo.\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
        "Because.\n```text\n## not a heading\n```\n\n## How to regenerate\n\n"
        "```text\npython studies/x/run.py --out y\npython3 tools/z.py\n```\n"
    )
    assert readme_section(page, "answer").split() == [
        "No.",
        "|",
        "a",
        "|",
        "b",
        "|",
        "|---|---|",
        "|",
        "1",
        "|",
        "2",
        "|",
        "Because.",
        "```text",
        "##",
        "not",
        "a",
        "heading",
        "```",
    ]
    assert answer_prose_lines(page) == 5
    assert readme_section(page, "status") == ""
    assert page_scripts(page) == ["studies/x/run.py", "tools/z.py"]


def test_benchmarks_hold_speed_measurements_only():
    names = sorted(
        p.name
        for p in (ROOT / "benchmarks").iterdir()
        if p.name != "__pycache__" and not p.name.startswith(".")
    )
    assert names and [n for n in names if not re.fullmatch(r"bench_\w+\.py", n)] == []
