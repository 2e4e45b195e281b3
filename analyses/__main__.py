"""``python -m analyses``: the ``coherence`` command line without the installed script."""
import sys

try:
    from analyses.cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line loads: the one line it prints later too, then die by it
    import os
    import signal

    sys.stderr.write("coherence: interrupted\n")
    sys.stderr.flush()
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGINT)

if __name__ == "__main__":  # importing the module (the API reference does) runs nothing
    sys.exit(main())
