"""Exception types of guidefit.

Every error that reaches the command line is a :class:`GuidefitError`; its
message is one line that names the file or field at fault, and its
``exit_code`` is what the CLI returns (2 bad input or usage, 1 a check or an
identification that failed on valid input). Every one also subclasses a
builtin, so library users can catch it as such: every input error is a
:class:`ValueError`, :class:`IdentificationError` a :class:`RuntimeError`.

The classes live here, or beside the module that owns their concept; every one
is in this table (``tests/test_errors.py`` checks it, and that each subclasses
:class:`GuidefitError` and a builtin):

=======================  ===========================  ==========================  ====
class                    home                         bases                       exit
=======================  ===========================  ==========================  ====
``GuidefitError``        ``guidefit.errors``          ``Exception``               2
``GuideError``           ``guidefit.errors``          ``ValueError``              2
``RecordingError``       ``guidefit.errors``          ``ValueError``              2
``ModelError``           ``guidefit.errors``          ``ValueError``              2
``IdentificationError``  ``guidefit.errors``          ``RuntimeError``            1
``CheckSpecError``       ``guidefit.report.check``           ``GuideError``              2
``HitSettingsError``     ``guidefit.hits``            ``ValueError``              2
``OutputError``          ``guidefit.outputs``         ``ValueError``              2
``ExportError``          ``guidefit.export.core``     ``ValueError``              2
``DeckError``            ``guidefit.machine.ccx_deck``        ``ValueError``              2
``UpdateError``          ``guidefit.machine.update``          ``DeckError``               2
``CorrelateError``       ``guidefit.machine.correlate``       ``ValueError``              2
``SetupError``           ``guidefit.io.setup``        ``RecordingError``          2
``FEResultError``        ``guidefit.io.fe_results``   ``ValueError``              2
=======================  ===========================  ==========================  ====
"""


class GuidefitError(Exception):
    """Base of every guidefit error; ``str(err)`` is a single line.

    Line breaks that reach a message from the input (a channel name with a
    newline, say) are shown escaped, so the promise holds whatever the file.

    >>> str(RecordingError("channel 'a\\nb' not recognised"))
    "channel 'a\\\\nb' not recognised"
    """

    exit_code = 2

    def __init__(self, *args, details=()):
        if args and isinstance(args[0], str):
            args = (args[0].replace("\r", "\\r").replace("\n", "\\n"), *args[1:])
        super().__init__(*args)
        #: What lies behind the one-line message (every warning of a failed identification, say):
        #: shown by ``identify --verbose`` and in its JSON, never in the line itself.
        self.details = tuple(str(d) for d in details)


class GuideError(GuidefitError, ValueError):
    """A guide definition (catalogue entry or TOML file) is invalid."""


class RecordingError(GuidefitError, ValueError):
    """A recording file does not follow the recording contract."""


class ModelError(GuidefitError, ValueError):
    """The model cannot be evaluated for the given inputs (e.g. load beyond capacity)."""


class IdentificationError(GuidefitError, RuntimeError):
    """Valid input, but no result can be trusted (no mode found, all hits rejected)."""

    exit_code = 1


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (its class name when it has none): what a one-line
    error quotes of a library's error.

    >>> first_line(OSError("Unable to open\\ndetails"))
    'Unable to open'
    """
    text = str(exc).strip().splitlines()
    return text[0] if text else exc.__class__.__name__


#: Characters of run-level warnings an identification error quotes; all of them are its ``details``.
ERROR_REASON_CHARS = 160


def identification_failure(text: str, warnings, hint: str = "") -> IdentificationError:
    """An :class:`IdentificationError` of one short line: ``text``, the last run-level reasons and
    ``hint`` (e.g. ``guidefit.io.axes.frame_hint``'s).

    The latest warnings come first: they are of the stage that failed (the fit that found
    no mode; each run's "no accepted hit"), the earlier ones of stages that went on. The
    per-hit warnings (each rejected hit) are left out of the line (the run's own reason
    counts them), as are reasons past :data:`ERROR_REASON_CHARS` characters; every
    warning stays in the error's ``details`` (``identify --verbose``, ``--json``).

    >>> err = identification_failure("r.h5: no run gave an FRF", [
    ...     "run 'v' hit 0: rejected: clipped: force (13 samples at 2047.94 N)",
    ...     "run 'v': no accepted hit to average (1 rejected: clipped x1)"])
    >>> print(err)
    r.h5: no run gave an FRF (run 'v': no accepted hit to average (1 rejected: clipped x1); 1 more warning(s): --verbose)
    >>> len(err.details)
    2
    """
    import textwrap

    why = [w for w in reversed(warnings) if " hit " not in w.split(":", 1)[0]]  # run-level reasons, not each hit
    shown: list[str] = []
    for w in why:
        if shown and sum(map(len, shown)) + len(w) > ERROR_REASON_CHARS:
            break
        shown.append(textwrap.shorten(w, ERROR_REASON_CHARS, placeholder=" ..."))
    left = len(warnings) - len(shown)
    more = f"; {left} more warning(s): --verbose" if shown and left else ""
    if shown:
        reason = f" ({'; '.join(shown)}{more})"
    else:
        reason = f" ({len(warnings)} warning(s): --verbose)" if warnings else " (no hits)"
    return IdentificationError(text + reason + hint, details=warnings)
