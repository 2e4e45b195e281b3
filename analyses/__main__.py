"""``python -m analyses``: the ``coherence`` command line without the installed script."""
import sys

try:
    from analyses.cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line loads: the one line it prints later too, then die by it
    # as analyses.interrupts.exit_by_sigint does, written out: that module may be the import just interrupted
    import os
    import signal

    sys.stderr.write("coherence: interrupted\n")
    sys.stderr.flush()
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGINT)
    sys.exit(130)  # only if the signal could not end the process (blocked): the status a shell would show

if __name__ == "__main__":  # importing the module (the API reference does) runs nothing
    sys.exit(main())
