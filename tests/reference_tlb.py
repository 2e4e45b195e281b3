"""A slow, obvious data TLB: a list of page numbers and the policy's rule, step by step.

not-last-used ("nlu"): a round-robin fill pointer that starts at entry 0;
a miss fills the entry it points at, or the next one if that entry served
the previous lookup; the pointer then moves one past the filled entry.
"fifo": the same without the skip. "lru": an empty entry if any (the
lowest), else the entry unused for longest.
"""


class ReferenceTlb:
    def __init__(self, entries, page_size, policy):
        self.entries = [None] * entries
        self.last_use = [0] * entries
        self.page_size = page_size
        self.policy = policy
        self.pointer = 0
        self.last = None  # entry of the previous lookup
        self.clock = 0
        self.hits = 0
        self.misses = 0

    def lookup(self, address):
        """Look the page of ``address`` up; True on a hit."""
        self.clock += 1
        page = int(address) // self.page_size
        if page in self.entries:
            entry = self.entries.index(page)
            self.hits += 1
            hit = True
        else:
            self.misses += 1
            hit = False
            if self.policy == "lru":
                if None in self.entries:
                    entry = self.entries.index(None)
                else:
                    entry = min(range(len(self.entries)), key=lambda e: self.last_use[e])
            else:
                entry = self.pointer
                if self.policy == "nlu" and entry == self.last:
                    entry = (entry + 1) % len(self.entries)
                self.pointer = (entry + 1) % len(self.entries)
            self.entries[entry] = page
        self.last_use[entry] = self.clock
        self.last = entry
        return hit
