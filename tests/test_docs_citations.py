"""The manual pages the repository cites exist: every page of ``docs/`` named by its path in
the package, the tests, the scripts, the README and the manual itself is a file of the
checkout, every "docs/physics.md section N" has a section N, and the README's table of manual
pages opens and lists every page.  (CHANGELOG.md is history: it names pages as they were.)"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: where citations of manual pages live: source, inputs, scripts and pages
CITING = ["mdgran", "tests", "benchmarks", "reference", "docs", "lammps_inputs", ".ci"]
SUFFIXES = {".py", ".md", ".in", ".cpp", ".h", ".toml", ".rst", ""}
DOC_PATH = re.compile(r"docs/[\w./-]+?\.md")
SECTION = re.compile(r"docs/([\w/-]+\.md),? section (\d+)")


def citing_files():
    """README.md and the text files under :data:`CITING` (no build output, no caches)."""
    yield ROOT / "README.md"
    for top in CITING:
        for path in sorted((ROOT / top).rglob("*")):
            skip = {"__pycache__", "_build", "auto_examples", "generated"} & set(path.parts)
            if path.is_file() and path.suffix in SUFFIXES and not skip:
                yield path


def citations():
    """(file, cited docs path, section or None) for every citation of a manual page."""
    found = []
    for path in citing_files():
        try:
            text = " ".join(path.read_text(encoding="utf-8").split())  # joins wrapped lines
        except UnicodeDecodeError:
            continue
        found += [(path, m.group(0), None) for m in DOC_PATH.finditer(text)]
        found += [(path, "docs/" + m.group(1), int(m.group(2))) for m in SECTION.finditer(text)]
    return found


def test_cited_pages_exist():
    cites = citations()
    assert any(doc == "docs/physics.md" for _, doc, _ in cites)  # the scan finds citations
    missing = sorted({f"{p.relative_to(ROOT)}: {doc}" for p, doc, _ in cites
                      if not (ROOT / doc).is_file()})
    assert not missing, "cited manual pages that do not exist:\n" + "\n".join(missing)


def test_cited_sections_exist():
    cites = [(p, doc, n) for p, doc, n in citations() if n is not None]
    assert any(doc == "docs/physics.md" for _, doc, _ in cites)
    bad = []
    for path, doc, n in cites:
        page = ROOT / doc
        if not page.is_file() or not re.search(rf"^## {n}\. ", page.read_text(), re.M):
            bad.append(f"{path.relative_to(ROOT)}: {doc} section {n}")
    assert not bad, "cited sections that do not exist:\n" + "\n".join(sorted(set(bad)))


def readme_page_links():
    """The targets of the links in the README's table of manual pages."""
    text = (ROOT / "README.md").read_text()
    table = text[text.index("## The manual"):].split("\n## ")[0]
    return re.findall(r"\]\((docs/[^)#]*)\)", table)


@pytest.mark.parametrize("target", readme_page_links())
def test_readme_page_table_opens_pages(target):
    assert (ROOT / target).exists(), target


def test_readme_page_table_lists_every_page():
    listed = {Path(t).as_posix().rstrip("/") for t in readme_page_links()}
    pages = {p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md")}
    assert pages - listed == set(), "pages the README's table does not list"
