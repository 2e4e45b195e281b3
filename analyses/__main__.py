"""``python -m analyses``: the ``coherence`` command line without the installed script."""
import sys

from analyses.cli import main

sys.exit(main())
