"""Compilation options the kernels share.

:data:`NOT_INLINED` keeps a hot kernel a function of its own in every caller;
:data:`NO_REFCOUNTS` compiles a hot loop over bundles of arrays without
reference counting.

Numba's ``inline`` option works on its own IR; whether LLVM then inlines a
compiled callee into its caller depends on whether the callee's IR was at
hand: it is when the callee was compiled in the same process, not when it was
loaded from numba's cache. So one cached caller held the callee inlined and
another did not, and the inlined copy ran slower: inside
:func:`coherence.scheduler.run_schedule`, whose own state leaves the cache
simulator's loop too few registers, a run with the kernels inlined was
markedly slower than with them called (same code, same counts).

Numba has no option that only says "do not inline"; debug information is its
one switch that marks a function ``noinline`` (``numba.core.lowering``). The
other effects of ``debug=True`` are turned back off: variable lifetimes are
not extended, indices are not bounds-checked. The debug information itself
costs about half a second of compilation per kernel signature.
"""

NOT_INLINED = {"debug": True, "_dbg_extend_lifetimes": False, "boundscheck": False}

#: Compile without numba's reference counting (its NRT). A call that passes
#: bundles of arrays to a compiled function is costly in numba: every array
#: travels as some nine machine words (so the tracer's traversal took about
#: 300 of them per ray), and the callee takes a reference to each array on
#: entry and drops it on exit, two atomic operations per array: for a ray
#: that misses the scene, most of its cost. Inlining the callee into the
#: loop (numba's ``inline="always"``) removes the argument traffic but not
#: the references, taken anew on each pass; a loop compiled with this
#: option takes none.
#:
#: Only for functions that allocate nothing and return no arrays (a function
#: without reference counting cannot own memory): the caller allocates the
#: scratch and holds every array for the duration of the call.
NO_REFCOUNTS = {"_nrt": False}
