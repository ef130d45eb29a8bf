"""Every relative link and ``#anchor`` in the README and the docs resolves.

Targets must exist (file or folder), and an anchor must match a heading of its target file
under GitHub's slug rule. External links (http, https, mailto) and links inside code blocks
or inline code are skipped.
"""

from __future__ import annotations

import glob
import os
import re
from collections import Counter
from urllib.parse import unquote

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FILES = sorted(
    os.path.relpath(p, ROOT)
    for p in ["README.md", *glob.glob(os.path.join(ROOT, "docs", "*.md")),
              "experiments/results/README.md"]
    if os.path.exists(os.path.join(ROOT, p)))

FENCE = re.compile(r"^\s*(```|~~~)")
INLINE_CODE = re.compile(r"(`+).*?\1")
#: ``[text](target)`` and ``![alt](target)``, target up to whitespace or ``)``.
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lowercase, drop everything but letters, digits, spaces,
    hyphens and underscores (unicode letters kept), spaces to hyphens."""
    text = heading.strip().lower()
    text = "".join(c for c in text if c.isalnum() or c in " -_")
    return text.replace(" ", "-")


def prose_lines(text: str) -> list[str]:
    """The lines outside fenced code blocks and indented code (4 spaces after a blank line)."""
    out, fenced, prev_blank = [], False, True
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            out.append("")
            continue
        indented = line.startswith("    ") and prev_blank
        out.append("" if fenced or indented else line)
        prev_blank = (not line.strip()) or (indented and prev_blank)
    return out


def anchors(path: str) -> set[str]:
    """The anchors of a markdown file's headings; the n-th repeat of a slug gets ``-n``."""
    with open(path, encoding="utf-8") as f:
        lines = prose_lines(f.read())
    seen: Counter[str] = Counter()
    out = set()
    for line in lines:
        m = HEADING.match(line)
        if not m:
            continue
        s = slug(m.group(2))
        out.add(f"{s}-{seen[s]}" if seen[s] else s)
        seen[s] += 1
    return out


def links(path: str) -> list[str]:
    """The link targets in a markdown file's prose (not in code)."""
    with open(path, encoding="utf-8") as f:
        lines = prose_lines(f.read())
    return [m.group(1) for line in lines for m in LINK.finditer(INLINE_CODE.sub("", line))]


def broken(doc: str, root: str = ROOT) -> list[str]:
    """Each link of ``doc`` (relative to ``root``) whose file or anchor is missing."""
    base = os.path.dirname(os.path.join(root, doc))
    out = []
    for target in links(os.path.join(root, doc)):
        if re.match(r"^(https?|mailto):", target):
            continue
        path, _, anchor = target.partition("#")
        full = os.path.normpath(os.path.join(base, unquote(path))) if path else \
            os.path.join(root, doc)
        if not os.path.exists(full):
            out.append(f"{target}: no such file")
        elif anchor and (not full.endswith(".md") or unquote(anchor) not in anchors(full)):
            out.append(f"{target}: no such heading")
    return out


def test_slug_follows_github():
    assert slug("Fig. 5: α and the next subgoal") == "fig-5-α-and-the-next-subgoal"
    assert slug("Environments (`flrjax.envs`)") == "environments-flrjaxenvs"
    assert slug("Training (`python -m flrjax.train`)") == "training-python--m-flrjaxtrain"
    assert slug("  The paper's update ratio  ") == "the-papers-update-ratio"


def test_repeated_headings_and_code_are_handled(tmp_path):
    doc = tmp_path / "a.md"
    doc.write_text("# Notes\n\n## Notes\n\n```\n# Notes\n[x](missing.md)\n```\n\n"
                   "`[y](gone.md)` [ok](#notes-1) [bad](#notes-2) [web](https://x.org/#q)\n")
    assert anchors(str(doc)) == {"notes", "notes-1"}
    assert links(str(doc)) == ["#notes-1", "#notes-2", "https://x.org/#q"]


def test_broken_links_are_found(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("## Here\n")
    (tmp_path / "a.md").write_text("[1](docs/b.md#here) [2](docs/b.md#there) [3](docs/c.md)\n"
                                   "[4](docs/) [5](#top)\n# Top\n")
    assert broken("a.md", str(tmp_path)) == ["docs/b.md#there: no such heading",
                                             "docs/c.md: no such file"]


@pytest.mark.parametrize("doc", FILES)
def test_links_resolve(doc):
    assert broken(doc) == []
