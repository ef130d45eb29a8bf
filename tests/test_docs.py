"""Every relative link and ``#anchor`` in the README and the docs resolves.

A link's file or folder must exist, and its anchor must name a heading of the target Markdown
file under GitHub's rule for heading ids. Web links (http, https, mailto) are not checked.
"""

import os
import re
import urllib.parse
from collections.abc import Iterator

import pytest
from markdown_it import MarkdownIt

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_MD = MarkdownIt("commonmark").enable("table")
_NOT_SLUG = re.compile(r"[^\w\- ]")  # \w: unicode letters and digits, and "_"
_HTML_LINK = re.compile(r"""\b(?:href|src)\s*=\s*["']([^"']+)["']""", re.IGNORECASE)
_HTML_ID = re.compile(r"""\b(?:id|name)\s*=\s*["']([^"']+)["']""", re.IGNORECASE)


def doc_files() -> list[str]:
    """The Markdown files whose links the tests check, relative to the repository root."""
    docs = [os.path.join(d, f) for d, _, fs in os.walk(os.path.join(ROOT, "docs"))
            for f in fs if f.endswith(".md")]
    files = [os.path.join(ROOT, "README.md"), *docs,
             os.path.join(ROOT, "experiments", "results", "README.md")]
    return sorted(os.path.relpath(f, ROOT) for f in files if os.path.exists(f))


def slug(text: str) -> str:
    """GitHub's id for a heading's text: stripped, lowercased, every character but letters,
    digits, spaces, hyphens and underscores dropped, each space a hyphen."""
    return _NOT_SLUG.sub("", text.strip().lower()).replace(" ", "-")


def _heading_text(inline) -> str:
    """A heading's rendered text: its words and code spans, without link targets or markup."""
    return "".join(t.content for t in inline.children or [] if t.type in ("text", "code_inline"))


def anchors(markdown: str) -> set[str]:
    """The ids GitHub gives the headings of ``markdown`` (a repeated heading's later copies get
    ``-1``, ``-2``, ...), and the ids of explicit HTML anchors."""
    tokens = _MD.parse(markdown)
    seen: dict[str, int] = {}
    out: set[str] = set()
    for i, tok in enumerate(tokens):
        if tok.type == "heading_open":
            base = candidate = slug(_heading_text(tokens[i + 1]))
            while candidate in seen:
                seen[base] += 1
                candidate = f"{base}-{seen[base]}"
            seen[candidate] = 0
            out.add(candidate)
        elif tok.type in ("html_block", "html_inline"):
            out.update(_HTML_ID.findall(tok.content))
        for child in tok.children or []:
            if child.type == "html_inline":
                out.update(_HTML_ID.findall(child.content))
    return out


def links(markdown: str) -> Iterator[str]:
    """Every link and image target of ``markdown`` (inline, reference-style and HTML), not
    those inside code."""
    for tok in _MD.parse(markdown):
        if tok.type == "html_block":
            yield from _HTML_LINK.findall(tok.content)
        for child in tok.children or []:
            if child.type == "link_open":
                yield str(child.attrs["href"])
            elif child.type == "image":
                yield str(child.attrs["src"])
            elif child.type == "html_inline":
                yield from _HTML_LINK.findall(child.content)


def broken_links(path: str, root: str = ROOT) -> list[str]:
    """The links of the Markdown file ``path`` (relative to ``root``) that do not resolve,
    each with the reason."""
    with open(os.path.join(root, path), encoding="utf-8") as f:
        text = f.read()
    bad = []
    for link in map(urllib.parse.unquote, links(text)):
        if re.match(r"[a-z][a-z0-9+.-]*:", link, re.IGNORECASE):  # http:, https:, mailto:
            continue
        target, _, anchor = link.partition("#")
        if not target:
            full = os.path.join(root, path)
        elif target.startswith("/"):
            full = os.path.join(root, target.lstrip("/"))
        else:
            full = os.path.normpath(os.path.join(root, os.path.dirname(path), target))
        if not os.path.exists(full):
            bad.append(f"{link}: no such file or folder")
        elif anchor and full.endswith(".md"):
            with open(full, encoding="utf-8") as f:
                if anchor not in anchors(f.read()):
                    bad.append(f"{link}: no heading with this anchor")
    return bad


def test_slug_follows_github():
    assert slug("Environments (`flrjax.envs`)") == "environments-flrjaxenvs"
    assert slug(" Fig. 2 left: the tripod ") == "fig-2-left-the-tripod"
    assert slug("α = 0.01 collapses, DHRL reaches 0.80") == "α--001-collapses-dhrl-reaches-080"
    assert slug("Methods (`--algo`)") == "methods---algo"
    assert slug("run_grid.py") == "run_gridpy"


def test_anchors_number_repeated_headings_and_drop_markup():
    md = "# A\n\n## A\n\n## A\n\n### [Link](x.md) and `code`\n\n```\n# not a heading\n```\n"
    assert anchors(md) == {"a", "a-1", "a-2", "link-and-code"}


def test_links_skip_code_and_find_references(tmp_path):
    (tmp_path / "b.md").write_text("# Title here\n")
    (tmp_path / "a.md").write_text(
        "[ok](b.md#title-here) [bad anchor](b.md#nope) [gone](c.md) [web](https://x.y/z)\n"
        "`[in code](d.md)` [ref][r] ![img](e.png) [self](#top) [no](#none)\n\n# Top\n\n[r]: f.md\n")
    assert broken_links("a.md", str(tmp_path)) == [
        "b.md#nope: no heading with this anchor", "c.md: no such file or folder",
        "f.md: no such file or folder", "e.png: no such file or folder",
        "#none: no heading with this anchor"]


@pytest.mark.parametrize("path", doc_files())
def test_every_relative_link_resolves(path):
    assert broken_links(path) == []
