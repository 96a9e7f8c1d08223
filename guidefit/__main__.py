"""``python -m guidefit`` and the ``guidefit`` program: the command line.

:func:`run` installs the Ctrl-C handling (:func:`guidefit.outputs.install_interrupt_handler`)
before anything heavy is imported, so an interrupt at any moment ends the program with
one line and exit 130; :func:`guidefit.cli.main` alone (click's test runner, library
users) leaves the process's signal handling as it is.
"""


def run() -> None:
    """The ``guidefit`` program."""
    import os
    import signal
    import sys

    from guidefit import outputs

    outputs.install_interrupt_handler()
    try:
        # A failure while an object is freed after the error was reported (h5py closing a file
        # on a full disk, a generator closed by Ctrl-C) adds no traceback: the command's own
        # line has said what went wrong.
        sys.unraisablehook = outputs.quiet_unraisable
        sys.excepthook = outputs.quiet_unraisable
        outputs.one_line_logging()  # a library's logging.warning (matplotlib's font cache) as one guidefit line
        from guidefit.cli import main

        main()
    except KeyboardInterrupt:
        outputs.interrupted_exit()
    except SystemExit as exc:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the command has ended; ignored stays ignored
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if outputs.interrupted():  # Ctrl-C came, whatever caught it on the way: 130
            outputs.interrupted_exit()
        if code == 0:
            raise
        # A failed command ends here without tearing the interpreter down: the error it reported
        # may hold h5py objects of a file whose write failed (full disk, file-size limit), and
        # freeing those crashes libhdf5 (segfault). Nothing is left to flush but the streams.
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed pipe: nothing more to say
                pass
        os._exit(code)


if __name__ == "__main__":
    run()
