"""The ``guidefit`` command line: thin click commands over the library.

Each command parses its options, calls one library function and renders the
result through :mod:`guidefit.report`. Heavy modules are imported inside the
commands so that ``guidefit --help`` starts fast. Exit status: 0 success,
1 a check or identification failed, 2 bad input or usage; errors are one line
on stderr, never a traceback.
"""

from __future__ import annotations

import os
import sys

import click

from guidefit import __version__
from guidefit.batch import (  # noqa: F401 - identify's batch machinery (_identify_one: what workers run)
    _check_spec,
    _identify_one,
    _judge_file,
    _map_files,
    _named_guide_error,
    _plot_targets,
    _show_file,
)

_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


class _Group(click.Group):
    """A click group that turns guidefit errors into one-line messages and exit codes."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """Usage errors (bad option, missing argument, unknown command) as one line, exit 2."""
        import warnings

        from guidefit.outputs import one_line_warning

        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            with warnings.catch_warnings():  # Python's warning text (file, line, source) is not for the user
                warnings.showwarning = one_line_warning
                code = super().main(args, prog_name, complete_var, False, **extra)
        except _NO_ARGS_IS_HELP as exc:  # bare `guidefit`: the help text, as click shows it
            exc.show()
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            where = f" (see '{exc.ctx.command_path} --help')" if exc.ctx is not None else ""
            message = " ".join(exc.format_message().split())
            click.echo(f"guidefit: error: {message}{where}", err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            click.echo(f"guidefit: error: {' '.join(exc.format_message().split())}", err=True)
            sys.exit(exc.exit_code)
        except click.exceptions.Abort as exc:
            if isinstance(exc.__context__, KeyboardInterrupt):
                _interrupted()
            click.echo("guidefit: aborted", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)

    def invoke(self, ctx):
        from guidefit.errors import GuidefitError

        try:
            return super().invoke(ctx)
        except GuidefitError as exc:
            click.echo(f"guidefit: error: {exc}", err=True)
            sys.exit(exc.exit_code)
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            click.echo(f"guidefit: error: {where}{exc.strerror or exc}", err=True)
            sys.exit(2)
        except KeyboardInterrupt:
            _interrupted()
        except RecursionError:  # a nested document deeper than any real input (readers say it where they can)
            click.echo("guidefit: error: input nested too deeply to read (recursion limit)", err=True)
            sys.exit(2)
        except (click.exceptions.Exit, click.ClickException, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - a bug of guidefit: still one line, never a traceback
            from guidefit.outputs import interrupted

            if interrupted():  # Ctrl-C broke something (an import reports it as ImportError)
                _interrupted()
            where = ""
            tb = exc.__traceback__
            while tb is not None and tb.tb_next is not None:
                tb = tb.tb_next
            if tb is not None:
                where = f" at {tb.tb_frame.f_code.co_filename.rsplit('/', 1)[-1]}:{tb.tb_lineno}"
            click.echo(f"guidefit: internal error: {type(exc).__name__}: {exc}{where} "
                       "(please report this with the input file)", err=True)
            sys.exit(1)


def _interrupted():
    """Ctrl-C: one line, exit 130; in the guidefit program at once (no exit handler may wait)."""
    from guidefit.outputs import handler_installed, interrupted_exit

    if handler_installed():
        interrupted_exit()
    click.echo("guidefit: interrupted", err=True)
    sys.exit(130)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="guidefit")
def main():
    """Joint stiffness and damping of linear rolling guideways from impact-hammer tests.

    \b
    guidefit predict --guide MRB35        analytic stiffness and natural frequencies
    guidefit identify recording.h5        K_V, K_H, c_V, c_H from a hammer test
    guidefit identify setup.toml          the same from your own DAQ files (a test setup:
                                          docs/recordings.md, "Your own DAQ files: quick start")
    guidefit explain recording.h5         trace model-measurement residuals to a physical effect
    """
    # The linear algebra here is many small matrices (modal fits); OpenBLAS's thread pool only
    # adds contention for them (measured 4x slower on 2 busy cores). The FFTs use scipy.fft's own
    # workers. An explicit setting in the environment wins.
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    # A damaged HDF5 file can make the HDF5 library loop for good while it reads the metadata:
    # the command line reads it in a forked child it gives up on after 30 s (exit 2, one line).
    # The library does not fork unless asked (fork is unsafe in a program with other threads).
    os.environ.setdefault("GUIDEFIT_HDF5_TIMEOUT_S", "30")


def _parse_load(text: str | None):
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3:
        raise click.BadParameter(f"expected FV,FH,M in N,N,N m (three numbers), got '{text}'", param_hint="--load")
    return values


def _guide_file(name):
    """The guide TOML a ``--guide`` names (an input of the command), None for a catalogue name."""
    return name if name and os.path.isfile(name) else None


def _refuse(outputs, inputs) -> None:
    """Exit 2 (one line) before any work when an output would overwrite a file the inputs read
    (a setup's DAQ files and an HDF5 file's linked files included: guidefit.outputs.files_read)."""
    from guidefit.outputs import refuse_inputs

    refuse_inputs(outputs, inputs)


#: what ``--plot`` writes (matplotlib's formats without optional packages)
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _plot_file(plot_path) -> None:
    """Exit 2 (one line) before any work when ``--plot`` names a file no figure can be written as."""
    if plot_path and os.path.splitext(str(plot_path))[1].lower() not in PLOT_SUFFIXES:
        raise click.BadParameter(f"'{plot_path}': a plot is written as {', '.join(PLOT_SUFFIXES)}",
                                 param_hint="--plot")


def _written(path):
    """Context manager: a temporary path beside ``path``, renamed onto it when complete."""
    from guidefit.outputs import replacing

    return replacing(path)


def _input_axis_map(func):
    """``--axis-map`` of an input file (one syntax with export's): the command runs with the file's axes
    turned into guidefit's (:func:`guidefit.io.axes.input_axes`); parsed before any work (exit 2)."""
    import functools

    @functools.wraps(func)
    def run(*args, input_axis_map=None, **kwargs):
        from guidefit.io.axes import input_axes, parse_axis_map

        rot = parse_axis_map(input_axis_map, error=click.BadParameter)
        with input_axes(rot):
            return func(*args, **kwargs)

    return click.option("--axis-map", "input_axis_map", metavar="x=AX,y=AX,z=AX",
                        help="The file's axes in guidefit's (x lateral, y vertical, z along the rail), e.g. "
                             "x=X,y=Z,z=-Y for a machine frame with Z up; for UFF, frf.h5 and recordings.")(run)


@main.command()
def guides():
    """List the built-in guide catalogue."""
    from guidefit import report
    from guidefit.model.guides import builtin_guides, load_guide

    report.print_guides([load_guide(name) for name in builtin_guides()])


@main.command()
@click.option("--guide", "guide_name", default="MRB35", show_default=True,
              help="Built-in guide name or path to a guide TOML file.")
@click.option("--load", "load_text", metavar="FV,FH,M",
              help="Static load: vertical force N (positive presses the carriage onto the rail), "
                   "lateral force N, roll moment N m.")
@click.option("--sweep", "sweep_text", is_flag=False, flag_value="auto", default=None, metavar="[Q:FROM:TO:N]",
              help="Stiffness and frequencies over a load range: Q (FV, FH in N; M in N m) from FROM to TO in "
                   "N loads, the other components from --load, e.g. --sweep FV:0:900:10. Bare --sweep: "
                   "0 to --load in 21 steps, or F_V from 0 to 90 % of lift-off.")
@click.option("--calibration", type=click.Choice(["nominal", "law"]), default="nominal", show_default=True,
              help="Roller stiffness: the guide's nominal K_n, or the contact law's own value.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="Write a PNG plot.")
def predict(guide_name, load_text, sweep_text, calibration, as_json, plot_path):
    """Analytic stiffness (Eq. 1-4) and natural frequencies (Eq. 5-23) of a guide.

    Three stiffnesses, each named: the static tangent at zero load, the static tangent at
    the given load, and the apparent single-DOF value 4 pi^2 M f^2 that identify would report.
    """
    from guidefit import report
    from guidefit.model.guides import load_guide
    from guidefit.predict import parse_sweep, predict_sweep
    from guidefit.predict import predict as run_predict

    _refuse([plot_path], [_guide_file(guide_name)])
    _plot_file(plot_path)
    sweep = None
    if sweep_text not in (None, "auto"):
        try:
            sweep = parse_sweep(sweep_text)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--sweep") from None
    guide = load_guide(guide_name)
    load = _parse_load(load_text)
    if sweep_text is not None:
        frame = predict_sweep(guide, calibration=calibration, direction_load=load, sweep=sweep)
        report.render_sweep(frame, as_json=as_json, plot_path=plot_path, guide_name=guide.name,
                            calibration=calibration)
        return
    result = run_predict(guide, load=load, calibration=calibration)
    report.render_prediction(result, as_json=as_json, plot_path=plot_path)


@main.command(name="plan")
@click.argument("setup", required=False, type=click.Path(dir_okay=False))
@click.option("--guide", "guide_name", help="Built-in guide name or guide TOML [default: the setup's, else MRB35].")
@click.option("--sensors", "layout", metavar="LAYOUT",
              help="A sensor layout instead of a setup: default (A-D, one axis per run), both, triax:A,C, side, "
                   "pair, single, or a layout TOML.")
@click.option("--hit", "hit_texts", multiple=True, metavar="RUN:x,y,z", help="Move a run's hammer point (m).")
@click.option("--no-search", is_flag=True, help="Skip the search for the best hit points and layout.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="Write the auto-MAC matrix (PNG).")
@_input_axis_map
def plan_cmd(setup, guide_name, layout, hit_texts, no_search, as_json, plot_path):
    """Before the test: which modes each run excites and reads, and which labels the layout decides by shape.

    SETUP is a test setup TOML (its DAQ files need not exist yet) or a recording; without it,
    --sensors on the default runs (vertical hit along -y on the top face, lateral along -x on the side).
    """
    from guidefit import report
    from guidefit.plan import plan
    from guidefit.simulate import layouts

    _refuse([plot_path], [setup, _guide_file(guide_name), _guide_file(layout)])  # a layout TOML too
    _plot_file(plot_path)
    hits = {}
    for text in hit_texts:
        name, position = layouts.parse_hit(text)
        if name in hits:
            raise click.BadParameter(f"run '{name}' given twice", param_hint="--hit")
        hits[name] = position
    result = plan(setup, guide=guide_name, layout=layout, hits=hits, search=not no_search)
    report.render_plan(result, as_json=as_json, plot_path=plot_path)


#: ``--fft-precision`` of ``identify`` and ``frf`` (the choices of guidefit.frf.PRECISIONS).
_fft_precision_option = click.option(
    "--fft-precision", type=click.Choice(["auto", "single", "double"]), default="auto", show_default=True,
    help="Precision the FFTs compute in; auto: that of the stored samples (float32 files: single).")


class _EstimatorChoice(click.Choice):
    """``--estimator``: the names of :data:`guidefit.frf.ESTIMATORS`, read when click first needs them
    (help, parsing), so that the CLI starts without importing numpy."""

    def __init__(self):
        super().__init__((), case_sensitive=True)

    @property
    def choices(self):
        from guidefit.frf import ESTIMATORS

        return tuple(ESTIMATORS)

    @choices.setter
    def choices(self, _value):  # click.Choice.__init__ assigns the (empty) tuple given above
        pass


#: ``--estimator`` of identify, frf, explain and report (the FRF estimators of guidefit.frf).
_estimator_option = click.option("--estimator", type=_EstimatorChoice(), default="H1", show_default=True)


def _identify_options(func):
    """The identify options that change numbers, shared by identify, explain and report."""
    func = _fft_precision_option(func)
    func = click.option("--no-jackknife", is_flag=True,
                        help="Skip the hit-group jackknife (faster, fit std only).")(func)
    return _estimator_option(func)


#: What identify imports after it has read a recording's metadata (the hit checks, the FFT engine,
#: the modal stage): imported while the forked metadata reader works (io.watchdog), not after it.
AFTER_METADATA_IMPORTS = ("scipy.fft", "concurrent.futures", "guidefit.hits", "guidefit.frf.spectra",
                          "guidefit.modal_stage", "guidefit.modes.globalfit", "guidefit.consistency")


def _identify_settings(estimator="H1", no_jackknife=False, fft_precision="auto", **extra):
    """The settings of the commands that identify (identify, explain, report), and the imports their
    identification needs, made while the recording's metadata is read (:data:`AFTER_METADATA_IMPORTS`)."""
    from guidefit.identify import IdentifySettings
    from guidefit.io import watchdog

    watchdog.IMPORTS_WHILE_WAITING = AFTER_METADATA_IMPORTS
    return IdentifySettings(estimator=estimator, jackknife=not no_jackknife, fft_precision=fft_precision, **extra)


def _candidate_names(candidates: str | None):
    """``--candidates a,b`` -> ["a", "b"] (checked against the effect library), None for all."""
    names = [c.strip() for c in candidates.split(",")] if candidates else None
    if names:
        from guidefit.model.effects import EFFECTS

        unknown = [n for n in names if n not in EFFECTS]
        if unknown:
            raise click.BadParameter(f"unknown effect '{unknown[0]}'; have {', '.join(EFFECTS)}",
                                     param_hint="--candidates")
    return names


@main.command(name="identify")
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option("--guide", "guide_name", help="Guide name or TOML (default: the file's guide attribute, else MRB35).")
@_estimator_option
@click.option("--json", "as_json", is_flag=True, help="One JSON object per file (JSON Lines) on stdout.")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), help="Write one row per file to this CSV.")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False), help="Same as --csv.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="PNG of FRFs, phase and coherence (several files: the file's stem is appended).")
@click.option("--check", "check_path", type=click.Path(dir_okay=False),
              help="Tolerance spec (TOML); exit 1 when a file is out of tolerance.")
@click.option("--junit", "junit_path", type=click.Path(dir_okay=False), help="Write the outcome as JUnit XML.")
@click.option("--jobs", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Files processed in parallel.")
@click.option("--no-jackknife", is_flag=True, help="Skip the hit-group jackknife (faster, fit std only).")
@click.option("-v", "--verbose", is_flag=True,
              help="After an error or a rejection, every warning behind it on stderr (--json has them always).")
@_fft_precision_option
@_input_axis_map
def identify_cmd(files, guide_name, estimator, as_json, csv_path, summary_path, plot_path, check_path,
                 junit_path, jobs, no_jackknife, verbose, fft_precision):
    """Identify K_V, K_H, c_V, c_H from hammer recordings (Eq. 24-29).

    FILES are recordings (.h5, .csv, UFF .uff/.unv, FRF files frf.h5) or test setups (.toml) that
    point at your own DAQ files (TDMS, MDF, MAT, WAV, CSV exports; pip install -e '.[daq]'):
    docs/recordings.md, "Your own DAQ files: quick start".
    """
    import time

    from guidefit import report

    plot_targets = _plot_targets(files, plot_path)
    summary_paths = [csv_path] if summary_path == csv_path else [csv_path, summary_path]  # "same as --csv"
    _refuse([*summary_paths, junit_path, *plot_targets.values()], [*files, check_path, _guide_file(guide_name)])
    _plot_file(plot_path)
    spec = _check_spec(check_path)
    settings = _identify_settings(estimator, no_jackknife, fft_precision)
    started = time.perf_counter()
    console = report._console(stderr=as_json)
    judged = []
    for path, answer in _map_files(files, guide_name, settings, jobs, console, keep_frfs=bool(plot_path)):
        judged.append(_judge_file(path, *answer, spec=spec, guide_name=guide_name))
        _show_file(judged[-1], console, as_json, verbose, plot_targets.get(path))
    for target in filter(None, {csv_path, summary_path}):
        with _written(target) as tmp:
            report.write_summary_csv([j.row for j in judged], tmp)
    if junit_path:
        from guidefit.report.check import junit_xml

        with _written(junit_path) as tmp:
            junit_xml([j.outcome for j in judged], tmp, time.perf_counter() - started)
    if len(files) > 1 and not as_json:
        report.render_batch_summary([j.row for j in judged], [j.outcome for j in judged], console)
    sys.exit(max((j.code for j in judged), default=0))


def _parse_window(text: str | None):
    """``auto`` | ``none`` | ``force=SECONDS,tau=SECONDS,end=FRACTION`` -> WindowSettings; None (not
    given) -> None: the default windows, and no word about them for an input that holds FRFs."""
    from guidefit.frf import WindowSettings

    if text is None:
        return None
    if text == "auto":
        return WindowSettings()
    if text == "none":
        return WindowSettings(none=True)
    keys = {"force": "force_window_s", "taper": "force_taper_s", "tau": "exp_tau_s", "end": "exp_end_fraction"}
    values = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        if key.strip() not in keys:
            raise click.BadParameter(f"'{item}': use auto, none or force=S,taper=S,tau=S,end=FRACTION",
                                     param_hint="--window")
        try:
            values[keys[key.strip()]] = float(value)
        except ValueError:
            raise click.BadParameter(f"'{item}': value must be a number", param_hint="--window") from None
    try:
        return WindowSettings(**values)
    except (TypeError, ValueError) as exc:
        raise click.BadParameter(str(exc), param_hint="--window") from None


@main.command(name="frf")
@click.argument("recording", type=click.Path(dir_okay=False))
@_estimator_option
@click.option("--window", "window_text", default=None,
              help="auto | none | force=S,taper=S,tau=S,end=FRACTION (force window, exponential tau or "
                   "its end level).  [default: auto; an input of FRFs has its own windows]")
@click.option("--out", "out_path", type=click.Path(dir_okay=False),
              help="frf.csv, frf.h5 or frf.uff (UFF-58, needs pyuff); default: a summary on the terminal.")
@_fft_precision_option
@_input_axis_map
def frf_cmd(recording, estimator, window_text, out_path, fft_precision):
    """FRFs (H1/H2/Hv) and coherence of every response channel of any recording.

    RECORDING is a recording (.h5, .csv, .uff) or a test setup (.toml) of your own DAQ files
    (docs/recordings.md, "Your own DAQ files: quick start").
    """
    from guidefit import report
    from guidefit.identify import IdentifySettings, frf_of_recording

    _refuse([out_path], [recording])
    settings = IdentifySettings(estimator=estimator, window=_parse_window(window_text),
                                fft_precision=fft_precision)
    frfsets, warnings = frf_of_recording(recording, settings)
    for w in warnings:
        click.echo(f"guidefit: warning: {w}", err=True)
    if out_path:
        from guidefit.io.frf_files import read_metadata
        from guidefit.io.registry import write_frfs

        # written whole by the registry's writer (guidefit.outputs), never onto the input (_refuse above)
        write_frfs(out_path, frfsets, recording=read_metadata(recording))  # a recording's or FRF file's runs
        click.echo(f"FRFs of {len(frfsets)} run(s) written to {out_path}")
    else:
        report.render_frf_summary(frfsets)
    _frf_incomplete(recording, frfsets, warnings)


def _frf_incomplete(recording, frfsets, warnings) -> None:
    """Exit 1 with one line per run of ``recording`` that gave no FRF (every hit rejected): the runs
    that gave one are shown or written, as identify keeps the parameters it found."""
    from guidefit.io.frf_files import read_metadata

    got = {f.run for f in frfsets}
    missing = [r.name for r in read_metadata(recording).runs if r.name not in got]
    for name in missing:
        why = next((w for w in warnings if w.startswith(f"run '{name}': ")), f"run '{name}': no FRF")
        click.echo(f"guidefit: frf incomplete: {recording}: {why}", err=True)
    if missing:
        sys.exit(1)


@main.command(name="explain")
@click.argument("recording", required=False, type=click.Path(dir_okay=False))
@click.option("--modes", "modes_path", type=click.Path(dir_okay=False),
              help="Identified modes instead of a recording (identify --json output or a hand-written list).")
@click.option("--guide", "guide_name", help="Guide name or TOML (default: the one the input names, else MRB35).")
@click.option("--candidates", help="Comma-separated effect names to try (default: the whole library).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="PNG: measured vs model frequencies (and FRFs) before and after.")
@_identify_options
@_input_axis_map
def explain_cmd(recording, modes_path, guide_name, candidates, as_json, plot_path, estimator, no_jackknife,
                fft_precision):
    """Trace the model-measurement residual to a physical effect; error before and after.

    RECORDING is a recording (.h5, .csv, .uff, frf.h5) or a test setup (.toml) of your own DAQ
    files (docs/recordings.md, "Your own DAQ files: quick start").
    """
    from guidefit import report
    from guidefit.explain import explain
    from guidefit.progress import progress_bar

    if (recording is None) == (modes_path is None):
        raise click.UsageError("give a RECORDING or --modes FILE (one of them)")
    _refuse([plot_path], [recording, modes_path, _guide_file(guide_name)])
    _plot_file(plot_path)
    names = _candidate_names(candidates)
    settings = _identify_settings(estimator, no_jackknife, fft_precision)
    source = modes_path or recording
    from guidefit.errors import GuideError

    ident = result = None
    with progress_bar("explaining", enabled=not as_json) as progress:
        try:
            if recording is not None:  # explain(recording) in two steps: the plot shows this identification
                from guidefit.explain import identify_for_explain

                ident = identify_for_explain(recording, guide=guide_name, settings=settings)
            if ident is None or ident.gate is None:  # a rejected identification: nothing to explain
                result = explain(source if ident is None else ident, guide=guide_name, candidates=names,
                                 progress=progress, settings=settings)
        except GuideError as exc:
            if guide_name is not None:
                raise
            raise _named_guide_error(source, exc) from None
    if result is None:  # as identify says it, and exit 1 (the modes are not those of a carriage on the guide)
        click.echo(f"guidefit: identification rejected: {recording}: {ident.gate}", err=True)
        sys.exit(1)
    if plot_path:
        with _written(plot_path) as tmp:
            report.plot_explanation_with_frf(result, tmp, ident)
    if as_json:
        click.echo(report.dump_json(result.to_dict()))
    else:
        report.render_explanation(result)
    unidentified = ident.unidentified if ident is not None else _unidentified_of(modes_path)
    if unidentified:  # explained on the modes found; a joint mode is missing
        for line in unidentified:
            click.echo(f"guidefit: identification incomplete: {source}: {line}", err=True)
        sys.exit(1)


def _unidentified_of(path) -> list[str]:
    """The ``unidentified`` lines of an ``identify --json`` result (incomplete identification), else []."""
    from guidefit.jsonio import read_json_documents

    docs = read_json_documents(path)
    lines = docs[0].get("unidentified") if len(docs) == 1 and isinstance(docs[0], dict) else None
    return [str(x) for x in lines] if isinstance(lines, list) else []


def _id_list(text: str | None, option: str):
    """``"101,102"`` -> [101, 102] (positive integers), None when not given."""
    if text is None:
        return None
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise click.BadParameter(f"'{text}': expected comma-separated integers", param_hint=option) from None
    if any(v < 1 for v in values):
        raise click.BadParameter(f"'{text}': ids must be positive", param_hint=option)
    return values


@main.command(name="export")
@click.argument("results", type=click.Path(dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["nastran", "ansys", "abaqus", "json", "calculix"]),
              default="json", show_default=True)
@click.option("--joint", type=click.Choice(["explained", "apparent"]), default="explained", show_default=True,
              help="explained: the joint of the explained model, rig effects (sensor mass, soft support) removed; "
                   "apparent: the raw Eq. 24-29 values of the test.")
@click.option("--explain", "explain_paths", multiple=True, type=click.Path(dir_okay=False),
              help="explain --json output to use (matched by file; default: each result's modes are explained).")
@click.option("--guide", "guide_name", help="Guide name or TOML (default: the one the results name).")
@click.option("--element", type=click.Choice(["matrix", "bush", "springs"]), default="matrix", show_default=True,
              help="matrix: full 6x6 K and C (DMIG, MATRIX27, coupled connector); bush: their diagonal (CBUSH, "
                   "COMBIN14, connector); springs: the paper's 1-D vertical and horizontal sets.")
@click.option("--units", type=click.Choice(["si", "mm-N-s", "mm-t-s"]), default="si", show_default=True)
@click.option("--axis-map", metavar="x=AX,y=AX,z=AX",
              help="Model axes (x lateral, y vertical, z along the rail) in the machine frame, e.g. x=X,y=Z,z=-Y.")
@click.option("--carriage-node", "carriage_nodes", metavar="ID,...", help="Carriage node id per carriage.")
@click.option("--rail-node", "rail_nodes", metavar="ID,...", help="Rail node id per carriage.")
@click.option("--first-element", default=30001, show_default=True, type=click.IntRange(1, None))
@click.option("--id-step", default=100, show_default=True, type=click.IntRange(1, None),
              help="Element ids per carriage.")
@click.option("--vertical", "n_vertical", default=4, show_default=True, type=click.IntRange(1, 10_000),
              help="springs: vertical elements per carriage.")
@click.option("--horizontal", "n_horizontal", default=8, show_default=True, type=click.IntRange(1, 10_000),
              help="springs: horizontal elements per carriage.")
@click.option("--assembly", type=click.Choice(["include", "reference"]), default="include", show_default=True,
              help="calculix: a file to *INCLUDE, or one runnable deck (joint, carriage body, rail fixed, "
                   "*FREQUENCY) that checks the joint with one ccx call.")
@click.option("--rot-node-offset", "rot_offset", default=50, show_default=True, type=click.IntRange(1, None),
              help="calculix: a node's rotations are the DOFs of node + this (its rigid body's ROT NODE).")
@click.option("-o", "--out", "out_path", type=click.Path(dir_okay=False), help="Write here instead of stdout.")
def export_cmd(results, fmt, joint, explain_paths, guide_name, element, units, axis_map, carriage_nodes,
               rail_nodes, first_element, id_step, n_vertical, n_horizontal, assembly, rot_offset, out_path):
    """Joints for a machine FEM model: 6x6 stiffness and damping per carriage (paper Fig. 10)."""
    from guidefit.export import export
    from guidefit.progress import progress_bar

    _refuse([out_path], [results, *explain_paths, _guide_file(guide_name)])
    with progress_bar("explaining carriages", enabled=joint == "explained") as progress:
        text = export(results, fmt, joint=joint, explanations=explain_paths, guide=guide_name, element=element,
                      units=units, axis_map=axis_map, carriage_nodes=_id_list(carriage_nodes, "--carriage-node"),
                      rail_nodes=_id_list(rail_nodes, "--rail-node"), first_element=first_element,
                      id_step=id_step, n_vertical=n_vertical, n_horizontal=n_horizontal, progress=progress,
                      assembly=assembly, rot_offset=rot_offset, skipped=(skipped := []))
    if out_path:
        from guidefit.outputs import write_text

        write_text(out_path, text)
    else:
        click.echo(text, nl=False)
    for line in skipped:  # the deck holds the other carriages; exit 1 says it is not every one
        click.echo(f"guidefit: identification failed: {line}", err=True)
    if skipped:
        sys.exit(1)


@main.command(name="correlate")
@click.argument("fe_path", metavar="FE", type=click.Path(dir_okay=False))
@click.argument("test_path", metavar="TEST", type=click.Path(dir_okay=False))
@click.option("--point-map", "point_map", type=click.Path(dir_okay=False),
              help="Lines 'test_point = fe_point' where the two sides name points differently.")
@click.option("--json", "as_json", is_flag=True, help="The table, MAC matrix and warnings as one JSON object.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="The MAC matrix as .png, .pdf or .svg.")
@click.option("--check", "checks", metavar="max_error_pct=N,min_mac=N",
              help="Exit 1 when a pair's |Eq. 34 error| or MAC is out of tolerance.")
@click.option("--band", "band", metavar="LO,HI",
              help="Hz where measured FRFs are fitted [default: 0.5x the lowest to 1.5x the highest FE mode].")
def correlate_cmd(fe_path, test_path, point_map, as_json, plot_path, checks, band):
    """FE against test natural frequencies (paper Table 3): Eq. 34 error and MAC per mode pair.

    FE: CalculiX .dat/.frd, Nastran .f06/.op2, or CSV; TEST: UFF-55 shapes or UFF-58 FRFs (.uff/.unv; FRFs
    fitted by the global estimator), guidefit frf.h5, guidefit JSON, or CSV.
    """
    import json

    from guidefit.machine import correlate as corr

    _plot_file(plot_path)
    _refuse([plot_path], [fe_path, test_path, point_map])
    tolerances = corr.parse_checks(checks)
    result = corr.run(fe_path, test_path, point_map, corr.parse_band(band))
    if plot_path:
        with _written(plot_path) as tmp:
            corr.plot_mac(result, tmp)
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=1, allow_nan=False))
    else:
        click.echo(corr.render_table(result), nl=False)
    bad = corr.failed_checks(result, tolerances)
    if bad:
        click.echo(f"guidefit: check failed: {'; '.join(bad)}", err=True)
        sys.exit(1)


@main.command(name="update")
@click.argument("deck", type=click.Path(dir_okay=False))
@click.argument("measured", type=click.Path(dir_okay=False))
@click.option("--param", "params", multiple=True, required=True, metavar="SEL:NAME[=LO..HI]",
              help="A joint factor to fit (repeatable): SEL joint1 | joint1,joint2 (shared) | all (shared) | each; "
                   "NAME K_V, K_H, K_pitch, K_yaw, K_roll or K; bounds as factors (default 0.1..10).")
@click.option("--point-map", "point_map", type=click.Path(dir_okay=False),
              help="Lines 'test_point = fe_point' where the two sides name points differently.")
@click.option("--freq-std", "freq_std", type=float, metavar="PCT",
              help="Measured frequencies' std, % (default: from the residual).")
@click.option("--units", type=click.Choice(["si", "mm-N-s", "mm-t-s"]),
              help="The deck's unit system; the guidefit joints must be in it.")
@click.option("--jobs", default=1, show_default=True, type=click.IntRange(1, 64), help="ccx runs at a time.")
@click.option("--ccx", "ccx", metavar="PATH", help="The CalculiX program [default: ccx on PATH].")
@click.option("--max-iterations", default=20, show_default=True, type=click.IntRange(1, 1000),
              help="Solver iterations (each one ccx run, plus one per parameter for the sensitivities).")
@click.option("-o", "--out-dir", "out_dir", type=click.Path(file_okay=False),
              help="Folder for the updated joint files NAME.updated.inp [default: beside the deck].")
@click.option("--json", "as_json", is_flag=True, help="Parameters, Table 3 before and after, as one JSON object.")
def update_cmd(deck, measured, params, point_map, freq_std, units, jobs, ccx, max_iterations, out_dir, as_json):
    """Update the guidefit joints of a CalculiX machine deck so its modes match measured ones.

    DECK: a ccx deck (*FREQUENCY step) that *INCLUDEs joints from guidefit export --format calculix;
    MEASURED: modes as correlate reads them (guidefit JSON, UFF-55, CSV).
    """
    import json
    from pathlib import Path

    from guidefit.machine import update as upd
    from guidefit.machine.ccx_deck import find_ccx, load_deck
    from guidefit.outputs import write_text
    from guidefit.progress import progress_bar

    loaded = load_deck(deck)
    if units and units != loaded.units:
        raise upd.UpdateError(f"{deck}: --units {units} but its guidefit joints are in {loaded.units}: units that "
                              "disagree; export the joints with --units " + units)
    upd.parse_params(params, len(loaded.joints))
    folder = Path(out_dir) if out_dir else Path(deck).parent
    if not folder.is_dir():
        raise upd.UpdateError(f"{folder}: output folder does not exist")
    outs = {jf.path: folder / f"{jf.path.stem}.updated.inp" for jf in loaded.joint_files}
    _refuse(list(outs.values()), [deck, measured, point_map, *loaded.files])
    find_ccx(ccx)
    with progress_bar("ccx runs") as bar:
        result = upd.update(deck, measured, params, point_map_path=point_map, freq_std_pct=freq_std, jobs=jobs,
                            ccx=ccx, progress=bar.advance, max_iterations=max_iterations)
    texts = upd.updated_texts(result, (Path(deck).name, Path(measured).name))
    for path, text in texts.items():
        write_text(outs[path], text)
        result.written.append(outs[path])
    for note in result.notes:
        click.echo(f"guidefit: warning: {note}", err=True)
    for group, reason in result.problems:
        click.echo(f"guidefit: warning: not identifiable: {', '.join(group)}: {reason}", err=True)
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=1, allow_nan=False, default=str))
    else:
        click.echo(upd.render(result), nl=False)
        for w in result.written:
            click.echo(f"wrote {w}")


@main.command(name="report")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="HTML file to write (self-contained, plots embedded).")
@click.option("--guide", "guide_name", help="Guide name or TOML (default: the file's guide attribute).")
@click.option("--candidates", help="explain: comma-separated effect names to try (default: the whole library).")
@_identify_options
@_input_axis_map
def report_cmd(recording, out_path, guide_name, candidates, estimator, no_jackknife, fft_precision):
    """One self-contained HTML report of the identify and explain results (the same calls, same settings).

    RECORDING is a recording (.h5, .csv, .uff, frf.h5) or a test setup (.toml) of your own DAQ
    files (docs/recordings.md, "Your own DAQ files: quick start").
    """
    from guidefit.progress import progress_bar
    from guidefit.report.html import write_report

    _refuse([out_path], [recording, _guide_file(guide_name)])
    settings = _identify_settings(estimator, no_jackknife, fft_precision)
    with progress_bar("identifying and explaining") as progress:
        results = write_report(recording, out_path, guide=guide_name, settings=settings,
                               candidates=_candidate_names(candidates), progress=progress)
    click.echo(f"report written to {out_path}")
    gate = getattr(results.identification, "gate", None)
    if gate:  # as identify: the report shows the modes, no joint parameters; exit 1
        click.echo(f"guidefit: identification rejected: {recording}: {gate}", err=True)
        sys.exit(1)
    unidentified = getattr(results.identification, "unidentified", ())
    for line in unidentified:  # as identify and explain: a joint mode the set-up sees was not found
        click.echo(f"guidefit: identification incomplete: {recording}: {line}", err=True)
    if results.explanation is None:  # explain failed: the report says so, and so does the exit status
        click.echo(f"guidefit: explain gave no result: {recording}: {results.explain_error}", err=True)
    if unidentified or results.explanation is None:
        sys.exit(1)


@main.command(name="convert")
@click.argument("source", type=click.Path(dir_okay=False))
@click.option("-o", "--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Recording to write in the contract format: .h5 (any runs), .csv (one run) or .uff.")
@click.option("--compression", type=click.Choice(["gzip", "lzf"]), help="HDF5 filter for the samples.")
def convert_cmd(source, out_path, compression):
    """Write a test setup (or any recording) to the recording contract; never onto an input.

    SOURCE is a test setup (.toml) that points at your own DAQ files (TDMS, MDF, MAT, WAV, CSV
    exports; pip install -e '.[daq]'), or any recording: docs/recordings.md, "Your own DAQ
    files: quick start".
    """
    from guidefit.io.setup import convert

    recording = convert(source, out_path, compression=compression)
    runs = ", ".join(f"{run.name} ({run.n_samples} samples, {run.n_channels} channels)" for run in recording.runs)
    click.echo(f"wrote {out_path}: {runs}")


@main.command(name="simulate")
@click.option("--guide", "guide_name", default="MRB35", show_default=True,
              help="Built-in guide name or path to a guide TOML file.")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Recording to write (.h5 or .csv); its truth goes to FILE.truth.json.")
@click.option("--effect", "effects", multiple=True, metavar="NAME:param=value,...",
              help="An effect the simulated carriage has (repeatable), e.g. added_mass:mass_kg=0.1.")
@click.option("--fault", "faults", multiple=True, metavar="NAME[:param=value,...]",
              help="A measurement fault (repeatable): double_hit, overload, loose_sensor, dropped_hit.")
@click.option("--hits", default=8, show_default=True, type=click.IntRange(1, 100_000), help="Hits per run.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed (same seed, same file).")
@click.option("--format", "file_format", type=click.Choice(["h5", "csv"]),
              help="File format [default: from the --out suffix]; CSV writes one file per run.")
@click.option("--runs", default="vertical,lateral", show_default=True, help="Runs to simulate, comma-separated.")
@click.option("--record-length", "record_s", default=0.1, show_default=True, type=float,
              help="Record length per hit, s.")
@click.option("--force", "force_n", default=None, metavar="MIN,MAX",
              help="Range of the hits' peak forces, N.  [default: 200,500, or less for a carriage that "
                   "would drive the accelerometers past half their range: chosen and said]")
@click.option("--layout", type=click.Choice(["hits", "signals"]), default="hits", show_default=True,
              help="One pre-triggered record per hit, or one continuous record.")
@click.option("--ideal", is_flag=True, help="No sensor noise, no quantisation, no clipping.")
@click.option("--sensors", "sensor_layout", default="default", show_default=True, metavar="LAYOUT",
              help="Accelerometers of each run: default (A-D, the hammer's axis in each run), both (x and y "
                   "at A-D), pair (A, C; one axis per run), single (A; one axis per run), triax:A,C (x, y, z "
                   "at the named points), side (lateral run: x at side-face points E-H), or a layout .toml file.")
@click.option("--hit", "hit_points", multiple=True, metavar="RUN:x,y,z",
              help="Move a run's hammer point, m in the carriage frame (repeatable), e.g. lateral:0.05,-0.012,0.")
def simulate_cmd(guide_name, out_path, effects, faults, hits, seed, file_format, runs, record_s, force_n,
                 layout, ideal, sensor_layout, hit_points):
    """Simulate a hammer test with known truth, written in the recording contract."""
    from guidefit.simulate import config_from_options, write_simulation

    config = config_from_options(runs=runs, hits=hits, record_s=record_s, force_n=force_n, layout=layout,
                                 faults=faults, ideal=ideal, sensor_layout=sensor_layout, hit_points=hit_points)
    out = write_simulation(out_path, guide_name, effects, config, seed, file_format=file_format, progress=True)
    if "force_choice" in out.truth:
        click.echo(out.truth["force_choice"]["message"])
    for path in out.recordings:
        click.echo(f"wrote {path}")
    click.echo(f"truth in {out.truth_path} (never read by identify)")


if __name__ == "__main__":  # pragma: no cover
    main()
