"""The documentation's links and the files, modules and make targets it names exist, and the
README stays short.

Every relative link and image in README.md, CHANGELOG.md and docs/**/*.md must name a file
(or folder) inside the repository: a link that climbs out of it (`../shared/...`) works only
on the machine it was written on. Web links (http, https, mailto) are not followed; a
link's '#anchor' is stripped before the file is looked up. Links inside code (fenced blocks
and `code spans`) are not links and are skipped.

A code span whose first word is a repository path must name something that exists, so that
a newcomer can open what the docs point at (issue 21). A path is a word ending in a file
name with one of PATH_SUFFIXES (`render/scene.py`, `simd.*`, `fuzz/fuzz_<name>.py`: `*` and
`<...>` match anything), or in `/` (a folder: `tests/release/`). It is looked up:
- with a folder (`render/scene.py`, `splats/layer.cpp`, `tests/render/test_packets.py`):
  from one of LOOKUP_ROOTS -- the repository, `splat_tracer/`, `splat_tracer/native/` or
  `tests/`, the prefixes the docs leave out;
- bare (`test_method.py`, `vec3.h`): anywhere in the repository.
A name after the path, `path::name` or `path: name`, must occur in the file as a word
(`splats/visibility.cpp::resolve_layer`). Paths under what a build writes (GENERATED: `build/`,
`dist/`...) and Blender's own files (BLENDERS_FILES) are not looked up.

Every `make T` and `python -m M` in code (spans and fenced blocks) must be a Makefile target
and a module: a repository module file (`tools.demo`: tools/demo.py) or, outside the
repository's packages, one the running Python can import (`pytest`).

Plain Python: no bpy, no native core.
"""
from __future__ import annotations

import functools
import importlib.util
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README_MAX_LINES = 200  # issue 21: a README a newcomer reads in five minutes

_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE_SPAN = re.compile(r"(`+)((?:(?!\1).)+?)\1")
# [text](target) and ![alt](target); the target may be <...> and may carry a "title"
_INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*(<[^>]*>|[^)\s]+)(?:\s+\"[^\"]*\")?\s*\)")
# [label]: target (reference definitions)
_REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
_EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")  # http:, https:, mailto:, ...


def markdown_files() -> list[Path]:
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md"]
    files += sorted((ROOT / "docs").rglob("*.md"))
    return [f for f in files if f.is_file()]


def numbered_lines(text: str):
    """(line number, line, inside a fenced code block) of every line but the fences themselves."""
    in_fence = False
    for number, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        yield number, line, in_fence


def links(text: str):
    """(line number, target) of every link and image outside code."""
    for number, line, fenced in numbered_lines(text):
        if fenced:
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


# --- Paths, modules and make targets named in code -----------------------------------------

PATH_SUFFIXES = ("py", "cpp", "h", "md", "toml", "ini", "txt", "json", "csv", "png", "cfg", "sh")
LOOKUP_ROOTS = (ROOT, ROOT / "splat_tracer", ROOT / "splat_tracer" / "native", ROOT / "tests")
GENERATED = ("build/", "dist/", "wheels/", ".venv/")  # what `make` writes: not in a clone
BLENDERS_FILES = {"blender_ext.py", "bl_extension_cli.py"}  # Blender's extension tooling, not ours
_SKIPPED_DIRS = {"build", "dist", "wheels", "__pycache__", "node_modules"}

# a path word: folders, then a file name with a known suffix (or `.*`), or a trailing slash
_PATH = re.compile(r"^(?:[\w*.-]+/)*(?:[\w*-][\w*.-]*\.(?:%s|\*)|[\w*-][\w*.-]*/)$" % "|".join(PATH_SUFFIXES))
_PLACEHOLDER = re.compile(r"<[^<>/\s]+>")  # fuzz_<name>.py, bpy-<version>/
_MAKE = re.compile(r"(?<![\w$(/.-])make\s+([a-z][\w-]*)")
_PYTHON_M = re.compile(r"python[\d.]*\s+-m\s+([\w.<>]+)")


def code_texts(text: str):
    """(line number, text, is a span) of every code span and every fenced line."""
    for number, line, fenced in numbered_lines(text):
        if fenced:
            yield number, line, False
            continue
        for match in _CODE_SPAN.finditer(line):
            yield number, match.group(2), True


def named_path(span: str):
    """(path, name or None) when the code span's first word is a repository path, else None."""
    span = span.strip()
    name = None
    for separator in ("::", ": "):
        if separator in span:
            span, name = (part.strip() for part in span.split(separator, 1))
            break
    words = span.split()
    if not words:
        return None
    path = _PLACEHOLDER.sub("*", words[0])
    if not _PATH.match(path) or path.startswith(GENERATED) or path in BLENDERS_FILES:
        return None
    if name is not None:
        name = re.split(r"[\s\[(]", name, 1)[0]  # test_x[param], f(args)
        if not re.fullmatch(r"\w+", name):
            name = None
    return path, name


@functools.lru_cache(maxsize=None)
def _repository_entries() -> tuple[Path, ...]:
    """Every file and folder of the repository, hidden and generated folders left out."""
    found = []
    for folder, dirs, files in os.walk(ROOT):
        dirs[:] = [d for d in dirs if not d.startswith(".") and d not in _SKIPPED_DIRS]
        found += [Path(folder) / f for f in files + dirs]
    return tuple(found)


def repository_files(name_pattern: str) -> list[Path]:
    """Files and folders anywhere in the repository whose name matches."""
    return [entry for entry in _repository_entries() if entry.match(name_pattern)]


def resolve(path: str) -> list[Path]:
    """What a path word names, by the rule in the module's text."""
    folder = path.endswith("/")
    pattern = path.rstrip("/")
    if "/" in pattern:
        hits = [hit for base in LOOKUP_ROOTS for hit in base.glob(pattern)]
    else:
        hits = repository_files(pattern)
    return [hit for hit in hits if hit.is_dir() == folder or (not folder and hit.is_file())]


def makefile_targets() -> set[str]:
    targets = set()
    for line in (ROOT / "Makefile").read_text(encoding="utf-8").splitlines():
        match = re.match(r"^([A-Za-z][\w.-]*(?:\s+[A-Za-z][\w.-]*)*)\s*:(?!=)", line)
        if match:
            targets.update(match.group(1).split())
    return targets


def module_exists(module: str) -> bool:
    parts = _PLACEHOLDER.sub("*", module).split(".")
    if (ROOT / parts[0] / "__init__.py").is_file():  # one of the repository's packages
        stem = "/".join(parts)
        return bool(list(ROOT.glob(stem + ".py")) + list(ROOT.glob(stem + "/__main__.py")))
    return "*" not in module and importlib.util.find_spec(parts[0]) is not None


def missing_names(path: Path) -> list[str]:
    """What is wrong with the files, modules and make targets one Markdown file names in code."""
    problems = []
    targets = makefile_targets()
    for number, code, is_span in code_texts(path.read_text(encoding="utf-8")):
        where = f"{path.relative_to(ROOT)}:{number}: `{code.strip()}`"
        named = named_path(code) if is_span else None
        if named:
            file_path, name = named
            hits = resolve(file_path)
            if not hits:
                problems.append(f"{where}: no such {'folder' if file_path.endswith('/') else 'file'} "
                                f"(looked up from {', '.join(str(b.relative_to(ROOT)) + '/' for b in LOOKUP_ROOTS)})")
            elif name and not any(re.search(r"\b%s\b" % re.escape(name), hit.read_text(encoding="utf-8"))
                                  for hit in hits if hit.is_file()):
                problems.append(f"{where}: {name} is not in {file_path}")
        for target in _MAKE.findall(code):
            if target not in targets:
                problems.append(f"{where}: the Makefile has no target {target!r}")
        for module in _PYTHON_M.findall(code):
            if not module_exists(module):
                problems.append(f"{where}: no module {module!r}")
    return problems


def test_the_docs_exist():
    names = {f.relative_to(ROOT).as_posix() for f in markdown_files()}
    assert {"README.md", "docs/installation.md", "docs/user-guide.md", "docs/python-api.md",
            "docs/architecture.md", "docs/results.md", "docs/development.md"} <= names


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve_inside_the_repository(path):
    problems = broken_links(path)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_named_files_modules_and_make_targets_exist(path):
    problems = missing_names(path)
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


def test_the_name_check_sees_what_it_should():
    """The path rule itself: what counts as a path, where it is looked up, what is skipped."""
    assert named_path("splats/visibility.cpp::resolve_layer") == ("splats/visibility.cpp", "resolve_layer")
    assert named_path("test_method.py::test_x[GENERAL]") == ("test_method.py", "test_x")
    assert named_path("setup.py build_ext --inplace") == ("setup.py", None)
    assert named_path("fuzz/corpus/<harness>/") == ("fuzz/corpus/*/", None)
    assert named_path("native/splats/splat_scene.*") == ("native/splats/splat_scene.*", None)
    for not_a_path in ("d_i/r_i", "(r - d)/r", "np.linalg.inv", "scene.splat_tracer", "build/sanitize/logs/",
                       "blender_ext.py build", "/usr/lib/libSystem.B.dylib", ".json", "1/ior"):
        assert named_path(not_a_path) is None, not_a_path
    assert resolve("render/scene.py") == [ROOT / "splat_tracer" / "render" / "scene.py"]
    assert resolve("splats/layer.cpp") == [ROOT / "splat_tracer" / "native" / "splats" / "layer.cpp"]
    assert resolve("render/test_packets.py") == [ROOT / "tests" / "render" / "test_packets.py"]
    assert resolve("vec3.h") and resolve("tests/release/") and resolve("simd.*")
    assert not resolve("render/no_such_file.py") and not resolve("test_no_such_test.py")
    assert not resolve("render/scene.py/")  # a file is not a folder
    assert module_exists("tools.demo") and module_exists("fuzz.fuzz_<name>") and module_exists("pytest")
    assert not module_exists("tools.no_such_tool")
    assert {"test", "test-release", "build"} <= makefile_targets()
    text = "\n".join(["`make test` and `make no-such-target`", "```sh", "python -m tools.demo", "```"])
    assert [(n, c) for n, c, _ in code_texts(text)] == [(1, "make test"), (1, "make no-such-target"),
                                                       (3, "python -m tools.demo")]
