"""MkDocs hook: the math of every page as MathML, converted at build time.

pymdownx.arithmatex (generic mode) wraps each formula in
<span class="arithmatex">\\(...\\)</span> or <div class="arithmatex">\\[...\\]</div>;
this hook turns the TeX inside into MathML with latex2mathml, which browsers
render natively: no script, font or stylesheet is fetched. A formula
latex2mathml cannot read stays as its TeX text, in a <code> element.
"""

from __future__ import annotations

import html
import logging
import re
from typing import Any

from latex2mathml.converter import convert

log = logging.getLogger("mkdocs.hooks.math")

_INLINE = re.compile(r'<span class="arithmatex">\\\((.*?)\\\)</span>', re.S)
_BLOCK = re.compile(r'<div class="arithmatex">\\\[(.*?)\\\]</div>', re.S)


def _mathml(tex: str, display: str) -> str:
    source = html.unescape(tex).strip()
    try:
        return convert(source, display=display)
    except Exception:  # latex2mathml raises many kinds on TeX it cannot read
        log.info("math kept as TeX text: %s", source[:60])
        return f"<code>{html.escape(source)}</code>"


def on_page_content(output: str, **_: Any) -> str:
    output = _BLOCK.sub(lambda m: f'<div class="math">{_mathml(m[1], "block")}</div>', output)
    return _INLINE.sub(lambda m: _mathml(m[1], "inline"), output)
