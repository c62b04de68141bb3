"""The docs match the code: every `raf ...` command line shown in the README and docs/ parses, and every
relative link and image points at a file that exists."""
import re
import shlex
from pathlib import Path

import pytest

from robotatfactory.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _code_blocks(text: str):
    yield from re.findall(r"```[a-z]*\n(.*?)```", text, re.S)


def _is_concrete(line: str) -> bool:
    """A command a user could paste: no placeholders (NAME, [...], ...) and no pipes."""
    return (line.startswith("raf ") and "..." not in line and "|" not in line and "[" not in line
            and not re.search(r"\b[A-Z]{3,}\b", line) and "/" not in line.split()[1])


def _raf_commands():
    seen = set()
    for doc in DOCS:
        text = doc.read_text()
        lines = [ln for block in _code_blocks(text)
                 for ln in block.replace("\\\n", " ").splitlines()]  # shell line continuations joined
        lines += re.findall(r"`(raf [^`]+)`", text)  # inline code
        for line in lines:
            line = line.split("#", 1)[0].strip().rstrip("&").strip()
            if _is_concrete(line) and (doc.name, line) not in seen:
                seen.add((doc.name, line))
                yield pytest.param(line, id=f"{doc.name}:{line[:60]}")


@pytest.mark.parametrize("line", list(_raf_commands()))
def test_documented_raf_commands_parse(line):
    argv = shlex.split(line)[1:]
    try:
        build_parser().parse_args(argv)
    except SystemExit as e:  # --help exits 0; argparse exits 2 on an unknown option or a bad value
        if e.code != 0:
            pytest.fail(f"documented command does not parse ({e.code}): {line}")


def test_there_are_documented_commands():
    assert len(list(_raf_commands())) >= 15


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_relative_links_and_images_exist(doc):
    for target in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
        if re.match(r"[a-z]+://|#|mailto:", target):
            continue
        path = (doc.parent / target.split("#", 1)[0]).resolve()
        assert path.exists(), f"{doc.name} links to {target}, which does not exist"
