"""Subcommands of the ``coherence`` command line, one module each."""
