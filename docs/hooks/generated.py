"""MkDocs hook: the parts of the site that are generated at build time, never typed by hand.

* ``<!-- cli-reference -->`` on a page becomes the ``--help`` text of ``hybridev``
  and of every subcommand, run from this source tree (so it is the parser's own
  text: nothing to keep in step by hand);
* ``<!-- api: hybridev.xxx -->`` becomes one mkdocstrings block (``::: module``)
  per module of that subpackage, found by walking the package, so a new module
  appears in the API reference without editing the docs;
* ``$$ ... $$`` blocks and ``\\( ... \\)`` spans (outside code) become MathML
  (latex2mathml), which browsers render natively: no JavaScript, no CDN, the
  site works offline;
* the committed figures of ``evaluation/<study>/figures/`` are served at
  ``results/figures/<study>/`` (the results pages, written by
  ``docs/scripts/gen_results.py``, link them there), without copying them
  into ``docs/``.
"""

from __future__ import annotations

import html
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_CLI = re.compile(r"^<!-- cli-reference -->$", re.M)
_API = re.compile(r"^<!-- api: (hybridev(?:\.\w+)*) -->$", re.M)
_FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.M | re.S)
_DISPLAY = re.compile(r"^([ \t]*)\$\$\n(.+?)\n[ \t]*\$\$$", re.M | re.S)
_INLINE = re.compile(r"\\\((.+?)\\\)")
_CODE_SPAN = re.compile(r"`[^`\n]+`")


def _help(args: list[str]) -> str:
    env = dict(os.environ, COLUMNS="90", PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    res = subprocess.run([sys.executable, "-m", "hybridev.cli", *args, "--help"], cwd=ROOT,
                         env=env, capture_output=True, text=True, timeout=120, check=True)
    return res.stdout.rstrip()


def cli_reference() -> str:
    """Markdown of ``hybridev --help`` and ``hybridev <command> --help`` for every command."""
    top = _help([])
    m = re.search(r"\{([\w,-]+)\}", top)
    if m is None:
        raise RuntimeError("hybridev --help lists no subcommands: the CLI reference is empty")
    parts = ["## `hybridev`", "", "```text", top, "```", ""]
    for cmd in m.group(1).split(","):
        parts += [f"## `hybridev {cmd}`", "", "```text", _help([cmd]), "```", ""]
    return "\n".join(parts)


def api_blocks(package: str) -> str:
    """One ``::: module`` block per module of ``package`` (the package itself first)."""
    path = ROOT.joinpath(*package.split("."))
    names = [package]
    for info in pkgutil.walk_packages([str(path)], prefix=f"{package}."):
        leaf = info.name.rsplit(".", 1)[-1]
        if not leaf.startswith("_"):
            names.append(info.name)
    return "\n\n".join(f"::: {n}" for n in names)


def _math(text: str) -> str:
    from latex2mathml.converter import convert

    def display(m):  # one line, at the block's indent (inside a list item too)
        tex = " ".join(m.group(2).split())
        return m.group(1) + convert(tex, display="block").replace("\n", "")

    def inline(m):  # in a span: Markdown takes a line starting with <math> for a block
        return f'<span class="math">{convert(html.unescape(m.group(1)))}</span>'.replace("\n", "")

    out, pos = [], 0
    for fence in _FENCE.finditer(text):  # leave code blocks alone
        out.append(_math_prose(text[pos:fence.start()], display, inline))
        out.append(fence.group(0))
        pos = fence.end()
    out.append(_math_prose(text[pos:], display, inline))
    return "".join(out)


def _math_prose(text: str, display, inline) -> str:
    text = _DISPLAY.sub(display, text)
    spans = []

    def keep(m):
        spans.append(m.group(0))
        return f"\0{len(spans) - 1}\0"

    text = _INLINE.sub(inline, _CODE_SPAN.sub(keep, text))
    return re.sub(r"\0(\d+)\0", lambda m: spans[int(m.group(1))], text)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if _CLI.search(markdown):
        markdown = _CLI.sub(lambda _m: cli_reference(), markdown)
    markdown = _API.sub(lambda m: api_blocks(m.group(1)), markdown)
    return _math(markdown)


def on_files(files, config):
    from mkdocs.structure.files import File

    for png in sorted(ROOT.glob("evaluation/*/figures/*.png")):
        study = png.parent.parent.name
        files.append(File.generated(config, f"results/figures/{study}/{png.name}",
                                    abs_src_path=str(png)))
    return files
