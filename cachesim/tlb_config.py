"""Configuration of a data TLB, and the 21164's.

A :class:`Tlb` is an option of :class:`cachesim.Hierarchy`; the kernels that
simulate it are in :mod:`cachesim.tlb`.
"""
from __future__ import annotations

from dataclasses import dataclass

from rtcommon.validate import InputError, require_int, require_number, require_power_of_two

TLB_POLICIES = ("nlu", "lru", "fifo")


@dataclass(frozen=True)
class Tlb:
    """A data TLB: a fully associative cache of page numbers, looked up on every access.

    Parameters
    ----------
    entries : int
        Number of entries, 1 to 4096.
    page_size : int
        Page size in bytes, a power of two of at least 512.
    miss_cycles : float
        Fixed cost of one miss in CPU cycles (the refill handler); a
        documented figure, never a fitted one (see :func:`alpha21164_dtb`).
    policy : {"nlu", "lru", "fifo"}
        Replacement: not-last-used (round robin that skips the entry used
        last, the 21164's), least recently used, or plain round robin
        (:mod:`cachesim.tlb` gives the exact rules).
    name : str
        Label for reports.

    One entry maps one page: mappings of several pages per entry (the
    21164's granularity hints) are not modelled; a larger ``page_size``
    stands in for them.
    """

    entries: int
    page_size: int
    miss_cycles: float
    policy: str = "nlu"
    name: str = "DTB"

    def __post_init__(self):
        object.__setattr__(self, "entries", require_int("Tlb.entries", self.entries, 1, 4096))
        object.__setattr__(self, "page_size", require_int("Tlb.page_size", self.page_size, 512))
        require_power_of_two("Tlb.page_size", self.page_size)
        object.__setattr__(self, "miss_cycles", require_number("Tlb.miss_cycles", self.miss_cycles, 0, "cycles"))
        if not isinstance(self.policy, str) or self.policy.lower() not in TLB_POLICIES:
            raise InputError(f"Tlb.policy must be one of {', '.join(TLB_POLICIES)}; got {self.policy!r}")
        object.__setattr__(self, "policy", self.policy.lower())
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputError(f"Tlb.name must be a non-empty string, got {self.name!r}")

    def to_dict(self) -> dict:
        return {"name": self.name, "entries": self.entries, "page_size": self.page_size,
                "policy": self.policy, "miss_cycles": self.miss_cycles}



# DTB miss penalty of the 21164, in CPU cycles, and how it is made up. The
# handler is the DTBMISS_SINGLE flow of Digital's EV5 OSF/1 PALcode (as kept
# in gem5, system/alpha/palcode/osfpal.S): 15 instructions laid out in dual-
# issue pairs, so 8 issue cycles, with a 1-cycle delay after reading VA_FORM
# and a load of the page-table entry (a D-cache hit: 2 cycles). Entering
# PALcode costs a TRAPB (typically 4 cycles) and 1 cycle of issue, as the
# PALcode entry table of the Alpha 21164PC hardware reference manual (section
# 6.4) gives for the 21164 family; the return (HW_REI) is assumed to cost the
# same 5. The page-table entry's own cache misses are not included.
DTB_HANDLER_ISSUE_CYCLES = 8
DTB_HANDLER_STALL_CYCLES = 1 + 2
DTB_TRAP_ENTRY_CYCLES = 4 + 1
DTB_TRAP_RETURN_CYCLES = 5
DTB_MISS_CYCLES = (DTB_HANDLER_ISSUE_CYCLES + DTB_HANDLER_STALL_CYCLES + DTB_TRAP_ENTRY_CYCLES
                   + DTB_TRAP_RETURN_CYCLES)


def alpha21164_dtb() -> Tlb:
    """The 21164's data TLB (DTB): 64 entries, fully associative, 8 KB pages, not-last-used.

    Facts from the Alpha 21164 hardware reference manual and the 21164PC's,
    whose DTB is the 21164's (section 2.1.4.1 and the DTB_TAG /
    DTB_PTE register descriptions, 5.2.3-5.2.4): 64 entries,
    fully associative, 8 KB pages, filled by PALcode, entry chosen by a
    not-last-used algorithm in hardware with a fill pointer that each fill
    advances. The exact rule modelled is in :mod:`cachesim.tlb`.

    Granularity hints (one entry mapping 8, 64 or 512 contiguous pages) are
    not modelled: they apply only where the operating system maps large
    physically contiguous regions with them, which we have no evidence a
    user process's heap received on the study's machine; one 8 KB page per
    entry is the plain case.

    The miss penalty, :data:`DTB_MISS_CYCLES` (21 cycles), is counted from
    the PALcode miss handler, not fitted: see the comment above it.
    """
    return Tlb(entries=64, page_size=8192, miss_cycles=DTB_MISS_CYCLES, policy="nlu", name="DTB")
