"""identify's batch machinery behind :mod:`guidefit.cli`: one file per worker, each answer judged and shown.

``guidefit identify FILE...`` maps :func:`_identify_one` over the files (in
worker processes with ``--jobs``: :func:`_map_files`, :func:`_pool_map`),
judges each answer (:func:`_judge_file`: the gate, a missing joint
parameter, ``--check``) and renders it (:func:`_show_file`). Kept apart
from the click commands so that the command module stays a list of thin
commands; it is of the same layer (command).
"""

from __future__ import annotations

import dataclasses
import os

import click


def _named_guide_error(path, exc):
    """A guide error caused by the guide a file names (no --guide given): say which file."""
    from guidefit.errors import GuideError

    return GuideError(f"{path}: the guide the file names: {exc}; choose one with --guide NAME or a guide TOML")


def _identify_one(path, guide, settings, keep_frfs=True):
    """Worker for one file: (exit code, Identification or None, error line, the error's details).

    ``keep_frfs`` False: the runs' FRF arrays are dropped from the result (only ``--plot`` draws
    them; a worker's result crosses a pipe, and large recordings give FRFs of 100 MB and more).
    """
    from dataclasses import replace

    from guidefit.errors import GuideError, GuidefitError
    from guidefit.identify import identify

    try:
        result = identify(path, guide=guide, settings=settings)
        if not keep_frfs:
            result = replace(result, runs=tuple(replace(run, frf=None) for run in result.runs))
        return 0, result, None, ()
    except GuideError as exc:
        if guide is None:
            exc = _named_guide_error(path, exc)
        return exc.exit_code, None, str(exc), exc.details
    except GuidefitError as exc:
        return exc.exit_code, None, str(exc), exc.details
    except Exception as exc:  # noqa: BLE001 - a batch goes on; the file is reported
        from guidefit.outputs import interrupted

        if interrupted():  # Ctrl-C broke something (an import reports it as ImportError)
            raise KeyboardInterrupt from None
        return 1, None, f"{path}: internal error: {type(exc).__name__}: {exc} (please report this file)", ()


def _plot_targets(files, plot_path) -> dict:
    """``--plot`` file per input: the path itself for one file, else with the input's stem appended."""
    from pathlib import Path

    if not plot_path:
        return {}
    return {path: plot_path if len(files) == 1 else str(
        Path(plot_path).with_stem(f"{Path(plot_path).stem}_{Path(path).stem}")) for path in files}


def _check_spec(check_path):
    """The ``--check`` tolerance spec (:func:`guidefit.report.check.load_spec`), None without the option."""
    if not check_path:
        return None
    from guidefit.report.check import load_spec

    try:
        return load_spec(check_path)
    except RecursionError:  # tomllib reads nested arrays recursively
        from guidefit.errors import GuidefitError

        raise GuidefitError(f"{check_path}: not a tolerance spec (arrays or tables nested too deeply)") from None


@dataclasses.dataclass(frozen=True)
class _Judged:
    """What identify says of one file: its exit code, the result or the error (and its details), the JSON
    object, the summary row and the ``--check`` violations."""

    path: str
    code: int
    result: object  # guidefit.identify.Identification or None
    error: str | None
    details: tuple
    data: dict
    row: dict
    violations: list

    @property
    def outcome(self) -> tuple:
        """(file, failures, error) for JUnit and the batch summary: check violations, gate, incomplete."""
        result = self.result
        gated = [f"identification rejected: {result.gate}"] if result is not None and result.gate else []
        gated += [f"identification incomplete: {line}" for line in (result.unidentified if result else ())]
        return str(self.path), self.violations + gated, self.error


def _judge_file(path, code, result, error, details, spec=None, guide_name=None) -> _Judged:
    """One file's identify answer (:func:`_identify_one`) judged: a gate, a missing joint parameter or
    a failed ``--check`` make exit 1 at least."""
    if result is None:
        data, row = _failed_json(path, guide_name, code, error, details), {"file": str(path), "error": error}
    else:
        data, row = result.to_dict(), result.summary_row()
        if result.gate is not None or result.unidentified:  # modes reported, joint parameters withheld or missing
            code = max(code, 1)
    violations = []
    if spec is not None and result is not None:
        from guidefit.report.check import check_result

        violations = check_result(data, spec)
        if violations:
            code = max(code, 1)
        data["check"] = {"passed": not violations, "violations": violations}
    return _Judged(path, code, result, error, details, data, row, violations)


def _show_file(judged: _Judged, console, as_json: bool, verbose: bool, plot_target=None) -> None:
    """Render one judged file: its lines on stderr, the plot, the table (or the JSON line on stdout)."""
    from guidefit import report
    from guidefit.outputs import replacing

    result, path = judged.result, judged.path
    if result is None:
        click.echo(f"guidefit: error: {judged.error}", err=True)
        _echo_details(judged.details, verbose)
    else:
        if result.gate is not None:  # modes reported, joint parameters withheld: identification failed
            click.echo(f"guidefit: identification rejected: {path}: {result.gate}", err=True)
            _echo_details(result.warnings, verbose)
        for line in result.unidentified:  # a joint parameter the set-up should give is missing
            click.echo(f"guidefit: identification incomplete: {path}: {line}", err=True)
        if plot_target:
            with replacing(plot_target) as tmp:
                report.plot_identification(result, tmp)
        if not as_json:
            report.render_identification(result, console)
    for line in judged.violations:
        click.echo(f"guidefit: check failed: {line}", err=True)
    if as_json:
        click.echo(report.dump_json(judged.data))


def _echo_details(details, verbose: bool) -> None:
    """With ``--verbose``: the warnings behind an error line, one per line on stderr."""
    for line in details if verbose else ():
        click.echo(f"guidefit:   {line}", err=True)


def _failed_json(path, guide_name, code, error, details=()) -> dict:
    """The JSON object of a file without a result: the contract's fields, every value null; its
    ``warnings`` are the error's details (every warning behind it), else the error line."""
    from guidefit.identify import joint_parameters

    guide = guide_name
    if guide is None:
        try:  # the file's own guide when its metadata can be read (e.g. every hit rejected)
            from guidefit.io.frf_files import read_metadata

            guide = read_metadata(path).guide or "MRB35"  # a recording's or an FRF file's
        except Exception:  # noqa: BLE001 - unreadable file: the guide is unknown
            guide = None
    return {"file": str(path), "guide": guide, "parameters": joint_parameters(1.0, {}), "modes": [],
            "warnings": list(details) or [error], "error": error, "exit_code": code, "gate": None,
            "sensor_faults": []}


def _map_files(files, guide_name, settings, jobs, console, keep_frfs=True):
    """Yield (path, (code, result, error, details)) in input order, in parallel when jobs > 1, with a
    progress bar; without ``keep_frfs`` the workers send their results without the FRF arrays."""
    from guidefit.progress import progress_bar

    with progress_bar("files", len(files), enabled=len(files) > 1, console=console) as progress:
        if jobs == 1 or len(files) == 1:
            for path in files:
                outcome = _identify_one(path, guide_name, settings)
                progress.advance()
                yield path, outcome
            return
        yield from _pool_map(files, guide_name, settings, jobs, progress, keep_frfs)


def _pool_map(files, guide_name, settings, jobs, progress, keep_frfs=True):
    """``_identify_one`` over ``files`` in ``jobs`` worker processes, results in input order.

    Ctrl-C and SIGTERM are the parent's: workers ignore SIGINT (blocked while they are forked,
    ignored by their initializer), and on an interrupt, a SIGTERM or an error the workers are
    killed, never waited for (a worker in the middle of a file would hold the exit for its whole
    run). A parent killed outright takes its workers with it (:func:`guidefit.workers.init_worker`).
    """
    import signal
    from concurrent.futures import ProcessPoolExecutor

    from guidefit.outputs import register_children
    from guidefit.workers import init_worker

    pool = ProcessPoolExecutor(max_workers=jobs, initializer=init_worker, initargs=(os.getpid(),))
    done = False
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:  # the workers are forked here (a SIGINT now waits for the unblock below)
            futures = [pool.submit(_identify_one, path, guide_name, settings, keep_frfs) for path in files]
            register_children(getattr(pool, "_processes", None) or {})
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        for path, future in zip(files, futures):
            outcome = future.result()
            progress.advance()
            yield path, outcome
        done = True
    finally:
        if done:
            pool.shutdown(wait=True)
        else:
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                process.kill()
            pool.shutdown(wait=False, cancel_futures=True)
