"""The documentation's links resolve, and the README stays short.

Every relative link and image in README.md, CHANGELOG.md and docs/**/*.md must name a file
(or folder) inside the repository: a link that climbs out of it (`../shared/...`) works only
on the machine it was written on. Web links (http, https, mailto) are not followed; a
link's '#anchor' is stripped before the file is looked up. Links inside code (fenced blocks
and `code spans`) are not links and are skipped.

Plain Python: no bpy, no native core.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README_MAX_LINES = 200  # issue 21: a README a newcomer reads in five minutes

_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")
# [text](target) and ![alt](target); the target may be <...> and may carry a "title"
_INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*(<[^>]*>|[^)\s]+)(?:\s+\"[^\"]*\")?\s*\)")
# [label]: target (reference definitions)
_REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
_EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")  # http:, https:, mailto:, ...


def markdown_files() -> list[Path]:
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md"]
    files += sorted((ROOT / "docs").rglob("*.md"))
    return [f for f in files if f.is_file()]


def links(text: str):
    """(line number, target) of every link and image outside code."""
    in_fence = False
    for number, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        line = _CODE_SPAN.sub("", line)
        for pattern in (_INLINE, _REFERENCE):
            for match in pattern.finditer(line):
                yield number, match.group(1).strip("<>")


def broken_links(path: Path) -> list[str]:
    """What is wrong with each relative link of one Markdown file."""
    problems = []
    root = ROOT.resolve()
    for number, target in links(path.read_text(encoding="utf-8")):
        if _EXTERNAL.match(target):
            continue
        file_part = target.split("#", 1)[0].split("?", 1)[0]
        if not file_part:  # an anchor in the same file
            continue
        where = f"{path.relative_to(ROOT)}:{number}: {target}"
        if file_part.startswith("/"):
            problems.append(f"{where}: absolute path (use a relative link)")
            continue
        resolved = (path.parent / file_part).resolve()
        if resolved != root and root not in resolved.parents:
            problems.append(f"{where}: points outside the repository")
        elif not resolved.exists():
            problems.append(f"{where}: no such file")
    return problems


def test_the_docs_exist():
    names = {f.relative_to(ROOT).as_posix() for f in markdown_files()}
    assert {"README.md", "docs/installation.md", "docs/user-guide.md", "docs/python-api.md",
            "docs/architecture.md", "docs/results.md", "docs/development.md"} <= names


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve_inside_the_repository(path):
    problems = broken_links(path)
    assert not problems, "\n".join(problems)


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


def test_the_link_check_sees_what_it_should():
    """The parser itself: links in code are skipped, a link that leaves the repository is not."""
    text = "\n".join([
        "[a](docs/a.md#x) ![b](<docs/b c.png> \"title\") [web](https://example.org) [here](#top)",
        "`[not](a/link.md)` and [ref]: ../outside.md",
        "```",
        "[inside](a/fence.md)",
        "```",
        "[ref2]: docs/c.md",
    ])
    assert list(links(text)) == [(1, "docs/a.md#x"), (1, "docs/b c.png"), (1, "https://example.org"),
                                 (1, "#top"), (6, "docs/c.md")]
