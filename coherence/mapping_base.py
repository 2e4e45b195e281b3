"""The base of every mapping: a frozen recipe that builds a Distribution, and what recipes share.

A :class:`Mapping` is a recipe (frozen, validated parameters); its
:meth:`Mapping.build` turns it into a concrete
:class:`~coherence.distribution.Distribution` of a ``width x height`` image
among ``n_processes``. The built-in recipes live in
:mod:`coherence.study_mappings`, :mod:`coherence.curve_mappings` and
:mod:`coherence.custom_mappings`; :mod:`coherence.mappings` names them.
"""
from __future__ import annotations

from rtcommon.validate import require_int, require_number

from .distribution import Distribution, _hand_over

#: Cycles one dynamic hand-out costs by default. An assumption, not a figure
#: from the study: a request/reply round trip to the master through shared
#: memory of about 20 µs at 300 MHz (the Alpha 21164 of the AlphaServer 8400).
DEFAULT_DISPATCH_CYCLES = 6000.0


class Mapping:
    """Base of work-distribution recipes.

    Subclasses are frozen dataclasses that validate their parameters and have
    a ``name`` (class attribute or property). They implement
    ``_build(width, height, n_processes) -> Distribution`` on validated
    arguments; users call :meth:`build`.
    """

    name: str  # provided by each subclass

    def build(self, width: int, height: int, n_processes: int) -> Distribution:
        """Distribute a ``width x height`` image among ``n_processes``.

        Raises
        ------
        ValueError
            If a size is not an integer >= 1.
        """
        owner = type(self).__name__
        width = require_int(f"{owner}.width", width, 1)
        height = require_int(f"{owner}.height", height, 1)
        n_processes = require_int(f"{owner}.n_processes", n_processes, 1)
        return self._build(width, height, n_processes)

    def _build(self, width: int, height: int, n_processes: int) -> Distribution:  # pragma: no cover
        raise NotImplementedError

    def picture(self, n_processes: int, width: int = 512, height: int = 512, ax=None):
        """Draw which process renders which pixel.

        Static mappings are coloured by process, dynamic ones by task index
        (their owner is only known at run time; the title says "dynamic").
        Colours repeat after 20 processes or tasks.

        Returns
        -------
        matplotlib.axes.Axes
        """
        import matplotlib.pyplot as plt
        from matplotlib.colors import ListedColormap

        dist = self.build(width, height, n_processes)
        image = dist.owner_image()
        n_values = dist.n_tasks if dist.dynamic else n_processes
        if n_values <= 10:
            colours = list(plt.get_cmap("tab10").colors)
        else:
            # tab20 pairs dark and light shades of a hue; all dark first keeps
            # neighbouring ids apart
            tab20 = list(plt.get_cmap("tab20").colors)
            colours = tab20[0::2] + tab20[1::2]
        n_colours = len(colours)
        if ax is None:
            _, ax = plt.subplots(figsize=(4, 4 * height / width))
        ax.imshow(
            image % n_colours,
            cmap=ListedColormap(colours),
            vmin=-0.5,
            vmax=n_colours - 0.5,
            interpolation="nearest",
        )
        if dist.dynamic:
            title = f"{dist.name}: dynamic, {dist.n_tasks} tasks (colour = task)"
        else:
            title = f"{dist.name}: {n_processes} process{'es' if n_processes != 1 else ''}"
        ax.set_title(title)
        ax.set_xticks([])
        ax.set_yticks([])
        return ax


def _static(name, width, height, n, offsets, pixels, process) -> Distribution:
    return Distribution(name, width, height, n, *_hand_over(offsets, pixels, process))


def _dynamic(mapping, width, height, n, offsets, pixels) -> Distribution:
    """The dynamic distribution of ``mapping`` (its dispatch cycles and take-ahead)."""
    return Distribution(mapping.name, width, height, n, *_hand_over(offsets, pixels), None,
                        dispatch_cycles=float(mapping.dispatch_cycles), take_ahead=int(mapping.take_ahead))


def _check_dynamic(owner: str, dispatch_cycles, take_ahead) -> None:
    require_number(f"{owner}.dispatch_cycles", dispatch_cycles, 0, "cycles")
    require_int(f"{owner}.take_ahead", take_ahead, 0)
