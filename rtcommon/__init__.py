"""Helpers every layer shares: atomic files, JSON values, versions, input checks.

The toolkit's packages form layers (``tracer`` and ``cachesim`` at the bottom,
``coherence`` joining them, ``analyses`` on top); ``rtcommon`` sits beneath
them all and imports none of them, so each helper has exactly one home:

- :mod:`rtcommon.files`: write a file atomically (temporary name, then rename);
- :mod:`rtcommon.jsonio`: numpy-aware JSON fallback and plain, rounded JSON values;
- :mod:`rtcommon.versions`: the package versions recorded with every result;
- :mod:`rtcommon.validate`: integer and number checks that raise ``InputError`` (a ``ValueError``)
  naming the field and the allowed range;
- :mod:`rtcommon.jit`: compilation options the kernels share.
"""
