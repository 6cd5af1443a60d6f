"""Every ```python block of the README and the docs runs as written (blocks of one page share a namespace,
in order, in a fresh folder). Blocks that need hardware CI lacks (a GPU) are fenced ```py instead."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _pages_with_snippets():
    return [page for page in PAGES if BLOCK.search(page.read_text())]


@pytest.mark.parametrize("page", _pages_with_snippets(), ids=lambda page: str(page.relative_to(ROOT)))
def test_snippets_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__snippet__"}
    for number, code in enumerate(BLOCK.findall(page.read_text()), 1):
        try:
            exec(compile(code, f"{page.name} block {number}", "exec"), namespace)
        except Exception as error:
            raise AssertionError(f"{page.relative_to(ROOT)}, python block {number} fails: {error!r}") from error


def test_every_page_is_checked():
    assert ROOT / "README.md" in _pages_with_snippets()
