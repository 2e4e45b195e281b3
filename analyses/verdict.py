"""The verdict "load balance or coherence?" as text computed from a run table.

Every number printed in the verdict is also returned as a row of
:attr:`Verdict.numbers` with exactly the value printed, so a report can put
them in its result table and a test can find each one there.

Per mapping at ``n`` processes: the user speed-up and the three losses of
the efficiency decomposition (efficiency = load balance x coherence x
dispatch; loss = 1 - factor), e.g. "S reaches 4.71 and loses 41.2% to
imbalance and 0.8% to coherence". A negative coherence loss (processes
sharing a CPU warmed each other's caches) is a gain and said so. The
headline names the loss whose worst case over the mappings is largest.
``coherence report`` (one scene) and ``coherence paper`` (each scene) both
judge with :func:`verdict`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from coherence.simulation import STUDY_CPUS
from rtcommon.validate import InputError

__all__ = ["Verdict", "verdict", "format_percent", "format_speedup", "LOSSES"]

#: A dispatch loss below this (as a fraction) is not worth a clause.
DISPATCH_SHOWN = 5e-4

#: The process count a verdict judges: the study's machine's CPUs, one process each.
VERDICT_PROCESSES = STUDY_CPUS


def verdict_process_count(counts) -> int:
    """:data:`VERDICT_PROCESSES` if among ``counts``, else the largest count."""
    return VERDICT_PROCESSES if VERDICT_PROCESSES in counts else max(counts)

LOSSES = (("imbalance_loss", "load balance", "imbalance"),
          ("coherence_loss", "coherence", "coherence"),
          ("dispatch_loss", "dispatch overhead", "dispatch"))


@dataclass(frozen=True)
class Verdict:
    """Text and the numbers it quotes.

    Attributes
    ----------
    headline : str
        One sentence: which loss decided the speed-up.
    sentences : list of str
        One sentence per mapping.
    numbers : DataFrame
        Columns ``mapping``, ``n_processes``, ``metric``, ``value``: every
        number of the text, as printed (percentages in percent).
    n_processes : int
    decided_by : str
        ``"load balance"``, ``"coherence"`` or ``"dispatch overhead"``
        (``"nothing"`` when no mapping lost anything).
    worst : dict
        Loss column of :data:`LOSSES` (``"imbalance_loss"`` ...) ->
        ``(mapping, loss)``: the mapping losing most to it and that loss (a
        fraction, unrounded); the headline ranks these.
    """

    headline: str
    sentences: list
    numbers: pd.DataFrame
    n_processes: int
    decided_by: str
    worst: dict = field(default_factory=dict)

    @property
    def text(self) -> str:
        return " ".join([self.headline, *self.sentences])


def format_percent(fraction: float) -> str:
    """``fraction`` as a percentage: one decimal from 1% up, else two significant digits."""
    value = 100.0 * float(fraction)
    if not np.isfinite(value):
        return "nan"
    if value == 0.0:
        return "0"
    if abs(value) >= 1.0:
        return f"{value:.1f}"
    return np.format_float_positional(value, precision=2, unique=False, fractional=False, trim="-")


def format_speedup(speedup: float) -> str:
    """A speed-up as printed in a verdict: two decimals."""
    return f"{float(speedup):.2f}"


def verdict(runs: pd.DataFrame, n_processes: int = VERDICT_PROCESSES, order=None) -> Verdict:
    """Compute the verdict from a table of runs at ``n_processes``.

    Parameters
    ----------
    runs : DataFrame
        Needs columns ``mapping``, ``n_processes``, ``speedup_user``,
        ``imbalance_loss``, ``coherence_loss``, ``dispatch_loss`` and
        optionally ``dispatch_share`` (e.g. :attr:`coherence.StudyResult.runs`).
    n_processes : int
        Process count to judge.
    order : sequence of str, optional
        Mapping order of the sentences (default: the table's).

    Raises
    ------
    ValueError
        If the table has no run at ``n_processes``.
    """
    rows = runs[runs["n_processes"] == n_processes]
    if rows.empty:
        raise InputError(f"no runs with n_processes == {n_processes}; have {sorted(set(runs['n_processes']))}")
    names = list(dict.fromkeys(rows["mapping"]))
    if order is not None:
        names = [name for name in order if name in names] + [name for name in names if name not in order]
    numbers = []
    sentences = []

    def quote(mapping, metric, text):
        numbers.append({"mapping": mapping, "n_processes": int(n_processes), "metric": metric,
                        "value": float(text)})
        return text

    shown = {}  # (mapping, loss column) -> printed text
    for name in names:
        row = rows[rows["mapping"] == name].iloc[0]
        speedup = quote(name, "speedup_user", format_speedup(row["speedup_user"]))
        parts = []
        for column, _, short in LOSSES:
            value = float(row[column])
            text = format_percent(abs(value))
            if column == "dispatch_loss" and abs(value) < DISPATCH_SHOWN:
                continue  # static mappings hand nothing out; DB's one-process run pays the same share
            if value < 0:
                shown[(name, column)] = quote(name, f"{short}_gain_pct", text)
                parts.append(f"gains {text}% from {short}")
            else:
                shown[(name, column)] = quote(name, f"{short}_loss_pct", text)
                parts.append(f"loses {text}% to {short}")
        sentence = f"At {n_processes} processes {name} reaches a user speed-up of {speedup} and " + _join(parts)
        share = float(row["dispatch_share"]) if "dispatch_share" in row.index else 0.0
        if share > 0:
            sentence += f"; hand-outs take {quote(name, 'dispatch_share_pct', format_percent(share))}% of its work"
        sentences.append(sentence + ".")

    worst = {}
    for column, label, short in LOSSES:
        values = rows.set_index("mapping")[column].astype(float).reindex(names)
        mapping = values.idxmax()
        worst[column] = (float(values[mapping]), mapping, label, short)
    ranked = sorted(worst.items(), key=lambda item: -item[1][0])
    (first_column, (first_value, first_mapping, first_label, first_short)), \
        (second_column, (second_value, second_mapping, second_label, second_short)) = ranked[0], ranked[1]
    if first_value <= 0:
        headline = (f"At {n_processes} processes no mapping lost anything to imbalance, coherence or dispatch.")
        decided = "nothing"
    else:
        first_text = shown.get((first_mapping, first_column), format_percent(first_value))
        if second_value > 0 and (second_mapping, second_column) in shown:
            tail = (f"{second_short} at most {shown[(second_mapping, second_column)]}% ({second_mapping})")
        else:
            tail = f"no mapping lost anything to {second_short}"
        headline = (f"{first_label.capitalize()}, not {second_label}, decided the speed-up at {n_processes} "
                    f"processes: {first_short} cost up to {first_text}% ({first_mapping}), {tail}.")
        decided = first_label
    table = pd.DataFrame(numbers, columns=["mapping", "n_processes", "metric", "value"])
    return Verdict(headline, sentences, table, int(n_processes), decided,
                   {column: (mapping, value) for column, (value, mapping, _, _) in worst.items()})


def _join(parts: list) -> str:
    """Join clauses, dropping a verb that repeats the previous clause's ("loses a and b")."""
    words = []
    previous = None
    for part in parts:
        verb, rest = part.split(" ", 1)
        words.append(rest if verb == previous else part)
        previous = verb
    if len(words) <= 1:
        return "".join(words)
    return ", ".join(words[:-1]) + " and " + words[-1]
