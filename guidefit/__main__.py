"""``python -m guidefit`` and the ``guidefit`` program: the command line.

:func:`run` installs the Ctrl-C handling (:func:`guidefit.outputs.install_interrupt_handler`)
before anything heavy is imported, so an interrupt at any moment ends the program with
one line and exit 130; :func:`guidefit.cli.main` alone (click's test runner, library
users) leaves the process's signal handling as it is.
"""


def run() -> None:
    """The ``guidefit`` program."""
    import sys

    from guidefit import outputs

    outputs.install_interrupt_handler()
    try:
        sys.unraisablehook = outputs.quiet_unraisable
        from guidefit.cli import main

        main()
    except KeyboardInterrupt:
        outputs.interrupted_exit()
    finally:  # the command has ended: a Ctrl-C while the interpreter shuts down changes nothing
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)  # ignored stays ignored through finalisation


if __name__ == "__main__":
    run()
