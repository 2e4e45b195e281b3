"""What the self-contained HTML pages share: templates, tables and embedded figures.

Pages are Jinja2 templates under ``analyses/templates/`` (shipped as package
data), rendered with autoescaping on: every value from the data is escaped
unless a helper here has already made it safe HTML. Templates get two
filters, ``table`` (:func:`table_html`) and ``base64`` (PNG bytes to the
text of a ``data:`` URI), and the ``figure`` macro of ``page.html.j2``.
"""
from __future__ import annotations

import base64
import functools
import html
import io
import math

import numpy as np
import pandas as pd

__all__ = ["table_html", "figure_png", "png_base64", "render_page"]


def table_html(frame: pd.DataFrame, digits: int = 3):
    """A DataFrame as an HTML table: floats to ``digits`` decimals (whole
    numbers from a million up), integers with thousands separators, text
    escaped, NaN blank; wrapped in a horizontally scrolling ``div.wide``.

    Returns
    -------
    markupsafe.Markup
        Safe HTML, inserted by templates as it is.
    """
    from markupsafe import Markup

    def fmt(value):
        if isinstance(value, (float, np.floating)):
            if not math.isfinite(value):
                return ""
            return f"{value:,.{digits}f}" if abs(value) < 1e6 else f"{value:,.0f}"
        if isinstance(value, (int, np.integer)):
            return f"{int(value):,}"
        return html.escape(str(value))

    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    body = "".join("<tr>" + "".join(f"<td>{fmt(v)}</td>" for v in row) + "</tr>"
                   for row in frame.itertuples(index=False))
    return Markup(f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>')


def figure_png(fig, dpi: int = 90) -> bytes:
    """A matplotlib figure as PNG bytes, cropped to what is drawn.

    The PNG carries no ``Software`` entry (matplotlib's version), so the
    same figure gives the same bytes on any installation. Works on a bare
    :class:`matplotlib.figure.Figure`: no pyplot and no backend needed.
    """
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    return buffer.getvalue()


def png_base64(data: bytes) -> str:
    """PNG bytes as the base64 text of a ``data:image/png;base64,...`` URI."""
    return base64.b64encode(data).decode("ascii")


@functools.cache
def _environment():
    from jinja2 import Environment, PackageLoader, StrictUndefined

    environment = Environment(loader=PackageLoader("analyses", "templates"), autoescape=True,
                              undefined=StrictUndefined, keep_trailing_newline=True,
                              trim_blocks=True, lstrip_blocks=True)
    environment.filters["table"] = table_html
    environment.filters["base64"] = png_base64
    return environment


def render_page(template: str, **context) -> str:
    """Render ``analyses/templates/<template>`` with ``context``; a missing name is an error, not a blank."""
    return _environment().get_template(template).render(**context)
