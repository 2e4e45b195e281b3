"""Subcommands of the ``coherence`` command line, one module each; shared options in :mod:`.options`."""
