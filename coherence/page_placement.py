"""Physical page placement: which physical page frame the operating system gives each virtual page.

The Alpha 21164's S-cache and the board B-cache are indexed by physical
address (the 8 KB D-cache by virtual address, but its index lies inside the
8 KB page offset, so virtual and physical index agree there). With 8 KB pages
a 4 MB direct-mapped B-cache has 512 *page colours*: two pages conflict in it
when their frames have the same colour (frame number modulo 512). Which
frames the operating system hands out therefore decides conflict misses that
contiguous virtual arrays never show. Kessler and Hill ("Page placement
algorithms for large real-indexed caches", ACM TOCS 10(4), 1992) compare the
policies offered here:

``contiguous``
    Physical = virtual: the model without page placement (the default; no
    translation is made at all).
``colouring``
    Page colouring: every page gets a frame of its virtual page's colour, so
    the physical cache indexes as a virtual one would. For one address space
    it conflicts exactly as ``contiguous`` does (a test checks that); it
    differs from ``contiguous`` only in which frames, not which colours.
``bin-hopping``
    Pages get colours in the order they are first allocated, one colour
    after another, from wherever the allocator's hand stood (a seeded
    colour). Pages of the scene that hold no record (padding between
    regions) are never allocated and take no colour.
``random``
    Every page gets a colour drawn at random (seeded): the "arbitrary"
    placement of a free list that has been shuffled by other jobs.

Only the colour of a frame matters to a cache whose every way fits in the
colours' span of pages, which is how :meth:`PagePlacement.colours` chooses
their number from a hierarchy. A frame is built as ``virtual page << colour
bits | colour``: distinct virtual pages get distinct frames under every
policy, so no two pages ever share a line by accident.

Virtual pages are allocated in address order: the tracer builds its scene,
tree and index lists region by region, in the layout's order, before the
first pixel is rendered. All processes share the scene's physical pages (the
scene is built before the processes fork, and they only read it), so one
:class:`PageTable` serves every process of a run.

Other users' pages (the background load's streams, each a long-running job
reading on where its last slice stopped) are placed too. Under
``contiguous``, ``colouring`` and ``bin-hopping`` a stream's consecutive
pages have consecutive colours, from a seeded start: the stream as it is
without translation. Under ``random`` page ``k`` of background process
``b``'s stream gets the colour a hash of (seed, b, k) gives
(:func:`translate_stream`, :class:`BackgroundPages`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.validate import InputError, require_int, require_power_of_two

__all__ = ["PAGE_PLACEMENTS", "BackgroundPages", "PagePlacement", "PageTable", "identity_pages",
           "translate_addresses", "translate_stream"]

PAGE_PLACEMENTS = ("contiguous", "colouring", "bin-hopping", "random")


class PageTable(NamedTuple):
    """Physical frames of a range of virtual pages, as compiled code reads them.

    Attributes
    ----------
    first_page : int
        Virtual page number of ``frame[0]``.
    page_shift : int
        log2 of the page size.
    frame : ndarray of int64, shape (V,)
        Physical frame of virtual pages ``first_page .. first_page + V - 1``;
        shape (0,) for no translation (physical = virtual).
    """

    first_page: int
    page_shift: int
    frame: np.ndarray


def identity_pages() -> PageTable:
    """The :class:`PageTable` that translates nothing."""
    return PageTable(0, 13, np.zeros(0, dtype=np.int64))


#: Bits of a background stream's page number in its physical frames (:func:`translate_stream`).
STREAM_PAGE_BITS = 34


class BackgroundPages(NamedTuple):
    """How other users' streams are placed, as compiled code reads it.

    Attributes
    ----------
    page_shift : int
        log2 of the page size.
    colour_bits : int
        log2 of the page colours; -1: streams are not translated.
    seed : int
        Seed of the colours' hash.
    """

    page_shift: int
    colour_bits: int
    seed: int


@dataclass(frozen=True)
class PagePlacement:
    """How the operating system places pages in physical memory.

    Parameters
    ----------
    policy : {"contiguous", "colouring", "bin-hopping", "random"}
        See the module's description.
    page_size : int
        Bytes per page, a power of two (the 21164 under Digital UNIX: 8 KB).
    seed : int
        Seed of ``bin-hopping``'s starting colour and of ``random``'s colours.
    """

    policy: str = "contiguous"
    page_size: int = 8192
    seed: int = 0

    def __post_init__(self):
        if self.policy not in PAGE_PLACEMENTS:
            raise InputError(f"PagePlacement.policy must be one of {', '.join(PAGE_PLACEMENTS)}, "
                             f"got {self.policy!r}")
        require_int("PagePlacement.page_size", self.page_size, 512)
        require_power_of_two("PagePlacement.page_size", self.page_size)
        require_int("PagePlacement.seed", self.seed, 0)

    @property
    def translates(self) -> bool:
        """Whether physical addresses differ from virtual ones."""
        return self.policy != "contiguous"

    def colours(self, hierarchy) -> int:
        """Page colours of ``hierarchy``: pages spanned by its largest way, a power of two, at least 1.

        A way of ``size / assoc`` bytes is what one set index sweeps over; a
        frame's colour bits must cover it for the colour alone to decide where
        the page's lines fall in every level.
        """
        largest_way = max(level.n_sets * level.line_size for level in hierarchy.levels)
        pages = -(-largest_way // self.page_size)
        return 1 << max(pages - 1, 0).bit_length()

    def table(self, used_pages: np.ndarray, first_page: int, n_colours: int) -> PageTable:
        """The frames of ``used_pages.size`` virtual pages from ``first_page``.

        Parameters
        ----------
        used_pages : ndarray of bool, shape (V,)
            Pages that hold data (only those are allocated, in address order).
        first_page : int
            Virtual page number of ``used_pages[0]``.
        n_colours : int
            A power of two (:meth:`colours`).

        Returns
        -------
        PageTable
        """
        used_pages = np.asarray(used_pages, dtype=bool)
        require_power_of_two("n_colours", n_colours)
        shift = self.page_size.bit_length() - 1
        if not self.translates:
            return identity_pages()._replace(page_shift=shift)
        virtual = first_page + np.arange(used_pages.size, dtype=np.int64)
        colour_bits = n_colours.bit_length() - 1
        if self.policy == "colouring":
            colour = virtual % n_colours
        elif self.policy == "bin-hopping":
            hand = int(np.random.default_rng(self.seed).integers(n_colours))
            rank = np.cumsum(used_pages) - 1  # allocation order of the used pages
            colour = np.where(used_pages, (hand + rank) % n_colours, virtual % n_colours)
        else:
            colour = np.random.default_rng(self.seed).integers(0, n_colours, used_pages.size, dtype=np.int64)
        return PageTable(int(first_page), shift, (virtual << colour_bits) | colour)

    def background(self, n_colours: int) -> BackgroundPages:
        """The placement of other users' streams (translated only under ``random``)."""
        require_power_of_two("n_colours", n_colours)
        bits = n_colours.bit_length() - 1 if self.policy == "random" else -1
        return BackgroundPages(self.page_size.bit_length() - 1, bits, self.seed)

    def to_dict(self) -> dict:
        return {"policy": self.policy, "page_size": self.page_size, "seed": self.seed}


@njit(cache=True, nogil=True)
def translate_addresses(addresses, count, pages):
    """Replace ``addresses[:count]`` (uint64 byte addresses) by their physical addresses.

    Every address must lie in the pages of ``pages`` (a non-empty
    :class:`PageTable`); the offset within the page is kept.
    """
    shift = np.uint64(pages.page_shift)
    offset_mask = (np.uint64(1) << shift) - np.uint64(1)
    first = np.uint64(pages.first_page)
    frame = pages.frame
    for i in range(count):
        address = addresses[i]
        addresses[i] = (np.uint64(frame[(address >> shift) - first]) << shift) | (address & offset_mask)


@njit(cache=True, nogil=True, inline="always")
def _mixed(value):
    """SplitMix64's output function: a well-spread 64-bit hash of ``value`` (uint64)."""
    value = (value ^ (value >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    value = (value ^ (value >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return value ^ (value >> np.uint64(31))


@njit(cache=True, nogil=True)
def translate_stream(addresses, count, process, first_address, pages):
    """Place ``addresses[:count]`` of background process ``process``'s stream (uint64 byte addresses,
    the stream starting at ``first_address``) in random frames.

    Page ``k`` of the stream (counted from the page of ``first_address``) gets frame
    ``((process + 1) << STREAM_PAGE_BITS | k) << colour_bits | colour`` with ``colour`` the low
    ``colour_bits`` bits of ``_mixed(seed * 2**40 + process * 2**34 + k)``: distinct pages get
    distinct frames, and no frame of a stream is a frame of the scene (whose frames lie far below).
    """
    shift = np.uint64(pages.page_shift)
    offset_mask = (np.uint64(1) << shift) - np.uint64(1)
    colour_mask = (np.uint64(1) << np.uint64(pages.colour_bits)) - np.uint64(1)
    first_page = np.uint64(first_address) >> shift
    owner = np.uint64(process + 1) << np.uint64(STREAM_PAGE_BITS)
    key = (np.uint64(pages.seed) << np.uint64(40)) + (np.uint64(process) << np.uint64(STREAM_PAGE_BITS))
    for i in range(count):
        address = addresses[i]
        k = (address >> shift) - first_page
        colour = _mixed(key + k) & colour_mask
        frame = ((owner | k) << np.uint64(pages.colour_bits)) | colour
        addresses[i] = (frame << shift) | (address & offset_mask)
