"""Small HTML pieces shared by the self-contained report pages."""
from __future__ import annotations

import html
import math

import numpy as np
import pandas as pd


def table_html(frame: pd.DataFrame, digits: int = 3) -> str:
    """A DataFrame as an HTML table: floats to ``digits`` decimals (whole
    numbers from a million up), integers with thousands separators, text
    escaped, NaN blank; wrapped in a horizontally scrolling ``div.wide``."""
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
    return f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>'
