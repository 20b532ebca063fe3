"""``skelagnostic fit|validate|test|predict|evaluate``: task functions under a thin Hydra wrapper.

:func:`main` composes the config from the command line with Hydra and calls the
task function of the verb (:mod:`skelagnostic.cli.tasks`: ``fit(cfg)``,
``validate(cfg)``, ... each returning the run's metrics); it reports the result
or the error in one line, and cleans up after a failed run.

The config tree (the repository's ``conf/``) is installed as the package
``skelagnostic.conf``, so an installed ``skelagnostic`` works from any directory.
Plugin config paths (experiments, data presets) are added to Hydra's search path;
:func:`~skelagnostic.cli.model_configs.register_model_configs` stores each aligner's
configuration, read once from its plugin's file, in Hydra's ConfigStore. The command
is re-entrant from ``sys.argv`` alone, which Lightning's DDP launcher relies on: it re-executes
the same command line (plus ``hydra.run.dir=...``) for every extra rank.

Lightning and the run machinery (:mod:`~skelagnostic.cli.build`,
:mod:`~skelagnostic.cli.tasks`) are imported for a command that runs a job, not with
this module, so ``--help``, ``--cfg`` and ``--info`` answer without them; ``run``,
``RunMetrics``, ``TASKS``, ``MAX_SEED`` and ``build_datamodule`` are still importable
from here (on first use).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import shutil
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import hydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from skelagnostic.cli.allocator import kernel_time_hint
from skelagnostic.cli.model_configs import (
    ALIGNER_GROUP,
    explain_shadowed_model,
    register_model_configs,
)
from skelagnostic.cli.runs import (
    LOCK_FILE,
    RunDirectoryRefused,
    checkpoint_of,
    chosen_keys,
    max_steps_overrides,
    quiet_lightning,
    release_run_directories,
    reuse_run_config,
    run_of_overrides,
    summary_table,
    value_of,
)
from skelagnostic.cli.signals import SIGTERM_EXIT_CODE, Terminated
from skelagnostic.core.paths import expand_home_in_override
from skelagnostic.errors import ConfigError, SkelagnosticError, error_line, printable
from skelagnostic.filenames import SPLIT_FILE
from skelagnostic.lazy import lazy_exports
from skelagnostic.plugins import PluginManager, get_plugin_manager

__all__ = [
    "MAX_SEED",
    "TASKS",
    "ConfigError",
    "RunMetrics",
    "build_datamodule",
    "check_config_package",
    "compose",
    "evaluate",
    "fit",
    "main",
    "predict",
    "register_model_configs",
    "run",
    "split_hydra_flags",
    "test",
    "validate",
]
# The run machinery (Lightning, the builders, the task functions) is imported when a
# job runs, not with this module: ``skelagnostic fit --help`` stays as light as Hydra.
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "MAX_SEED": "skelagnostic.cli.tasks",
        "TASKS": "skelagnostic.cli.tasks",
        "RunMetrics": "skelagnostic.cli.tasks",
        "run": "skelagnostic.cli.tasks",
        "build_datamodule": "skelagnostic.cli.build",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic.cli.build import build_datamodule
    from skelagnostic.cli.tasks import MAX_SEED, TASKS, RunMetrics, run

#: Package holding the primary config ``config.yaml``.
CONFIG_MODULE = "skelagnostic.conf"
#: Set to ``1`` (or pass ``--debug``) for full tracebacks on configuration errors.
DEBUG_ENV = "SKELAGNOSTIC_DEBUG"


# ----------------------------------------------------------------- composition
def compose(
    overrides: Sequence[str] = (), task: str = "fit", plugin_manager: PluginManager | None = None
) -> DictConfig:
    """Compose the run config like the CLI does, for tests and notebooks.

    ``run_dir`` is not resolvable outside a Hydra run: set it, e.g.
    ``compose(["model=example", "run_dir=/tmp/run"])``.

    Args:
        overrides: Hydra overrides (``key=value``, ``group=option``, ``+key=value``).
        task: One of :data:`TASKS`.
        plugin_manager: Where aligners and config paths come from.

    Returns:
        The composed config.
    """
    pm = plugin_manager or get_plugin_manager()
    register_model_configs(pm)
    overrides = [expand_home_in_override(o) for o in overrides]
    with hydra.initialize_config_module(CONFIG_MODULE, version_base="1.3"):
        return hydra.compose(
            "config", overrides=[*_searchpath_overrides(pm, overrides), *overrides, f"task={task}"]
        )


def _searchpath_overrides(pm: PluginManager, args: Sequence[str]) -> list[str]:
    """``hydra.searchpath=[...]`` with the plugins' config paths (merged with the user's)."""
    paths = list(pm.config_paths)
    if not paths:
        return []
    for arg in args:
        if arg.split("=", 1)[0].lstrip("+~") == "hydra.searchpath":
            parsed = OverridesParser.create().parse_override(arg)
            paths = [*parsed.value(), *paths]
    quoted = ",".join(f"'{p}'" for p in dict.fromkeys(paths))
    return [f"hydra.searchpath=[{quoted}]"]


# ------------------------------------------------------------------ the CLI verbs
@contextlib.contextmanager
def _patched(argv: list[str], env: dict[str, str]) -> Iterator[None]:
    old_argv, old_env = sys.argv, {k: os.environ.get(k) for k in env}
    sys.argv = argv
    os.environ.update(env)
    try:
        yield
    finally:
        sys.argv = old_argv
        for k, v in old_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


#: Loggers that print by themselves instead of propagating to the root logger (Lightning
#: sets them up so when it is imported before logging is configured).
_OWN_HANDLER_LOGGERS = ("lightning.pytorch", "lightning.fabric")


@contextlib.contextmanager
def _job_log() -> Iterator[logging.Logger]:
    """Copy the run's log lines into Hydra's job log (``<run_dir>/app.log``) within the block.

    Hydra gives the root logger a file handler, but Lightning's loggers (``Seed set to
    42``, the data sets, the trainer's messages) print through their own handler and do
    not propagate, so the file stayed empty. Within the block the root's file handlers
    are also theirs (the console output is unchanged), and the logger yielded writes to
    the file only (the end of the run, which the console shows as a table).
    """
    files = [h for h in logging.getLogger().handlers if isinstance(h, logging.FileHandler)]
    loggers = [logging.getLogger(name) for name in _OWN_HANDLER_LOGGERS]
    quiet = logging.getLogger("skelagnostic.run")
    quiet.propagate = False
    quiet.setLevel(logging.INFO)
    added = [
        (logger, handler)
        for logger in [*[lg for lg in loggers if not lg.propagate], quiet]
        for handler in files
        if handler not in logger.handlers
    ]
    for logger, handler in added:
        logger.addHandler(handler)
    try:
        yield quiet
    finally:
        for logger, handler in added:
            logger.removeHandler(handler)


#: Files a run directory holds before it produced anything (Hydra's and ours).
_BOOKKEEPING = frozenset(
    {
        ".hydra/config.yaml",
        ".hydra/hydra.yaml",
        ".hydra/overrides.yaml",
        "app.log",
        "config.yaml",
        "csv/hparams.yaml",
        LOCK_FILE,
        SPLIT_FILE,
    }
)


def _discard_failed_run(run_dir: Path) -> str:
    """After a failure: delete ``run_dir`` if it holds only bookkeeping files.

    A run directory with anything else (checkpoints, logged metrics, renders,
    files of an earlier run) is kept so the run can be inspected or resumed.

    Returns:
        Text appended to the error line.
    """
    from lightning.pytorch.utilities import rank_zero_only  # the failed job loaded it

    cwd = Path.cwd()
    if rank_zero_only.rank != 0 or not run_dir.is_dir() or run_dir.resolve() in (cwd, *cwd.parents):
        return ""
    files = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if not p.is_dir()}
    kept = sorted(f for f in files if f not in _BOOKKEEPING and not f.endswith(".log"))
    if kept:
        last = run_dir / "checkpoints" / "last.ckpt"
        hint = f"; resume with ckpt_path={last}" if last.is_file() else ""
        return f" [run directory kept: {run_dir}{hint}]"
    shutil.rmtree(run_dir, ignore_errors=True)
    return ""


def check_config_package(module: str = CONFIG_MODULE) -> None:
    """Fail with a clear message when the config package has no ``config.yaml``.

    The config tree is installed as ``skelagnostic.conf`` from the top-level
    ``conf/``. An editable checkout updated from a version that kept it in
    ``src/skelagnostic/conf/`` can keep that directory (git leaves its
    ``__pycache__``), and Python then imports it as an empty namespace package
    that hides the real one; Hydra's own message ("Cannot find primary config")
    does not say why.

    Raises:
        ConfigError: The package cannot be imported or holds no ``config.yaml``.
    """
    import importlib.util

    spec = importlib.util.find_spec(module)
    places = list(spec.submodule_search_locations or []) if spec else []
    if any((Path(place) / "config.yaml").is_file() for place in places):
        return
    where = ", ".join(places) or "nowhere"
    raise ConfigError(
        f"the config package {module} (found at {where}) has no config.yaml; if that is a "
        "leftover src/skelagnostic/conf/ directory of an older checkout, delete it (the "
        "configs now live in the top-level conf/), then reinstall with pip install -e ."
    )


@contextlib.contextmanager
def _hidden_groups_in_help(flags: Sequence[str]) -> Iterator[None]:
    """Leave the internal ``_aligner`` group out of ``--help``'s list of config groups.

    Hydra lists every group of the search path; ``_aligner/<name>`` only carries an
    aligner's data and trainer options (selected from ``model=``), so it is not a
    choice for users. Other output passes through unchanged.
    """
    if not {"--help", "-h"} & set(flags):
        yield
        return
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stdout(buffer):
            yield
    finally:
        hidden = f"{ALIGNER_GROUP}: "
        sys.stdout.write(
            "".join(
                line
                for line in buffer.getvalue().splitlines(keepends=True)
                if not line.startswith(hidden)
            )
        )


def split_hydra_flags(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split a command line into Hydra's flags (with their values) and its overrides.

    Hydra parses ``sys.argv`` with argparse, which takes the overrides as one
    contiguous run of positional arguments; the CLI adds overrides of its own
    (``task=<verb>``, the plugins' search path), so it re-orders the user's
    arguments as flags first, overrides after. Flags and their arity come from
    Hydra's own argument parser: ``--cfg job``, ``--cfg=job``, ``-m``,
    ``--info`` with or without a value, ...

    Args:
        args: The arguments after the verb, in the user's order.

    Returns:
        ``(flags, overrides)``, each in the user's order.

    Example:
        >>> split_hydra_flags(["model=example", "--cfg", "job", "-m", "seed=1,2"])
        (['--cfg', 'job', '-m'], ['model=example', 'seed=1,2'])
    """
    from hydra._internal.utils import get_args_parser

    actions = get_args_parser()._option_string_actions
    flags: list[str] = []
    overrides: list[str] = []
    tokens = list(args)
    i = 0
    while i < len(tokens):
        token = tokens[i]
        i += 1
        name = token.split("=", 1)[0]
        if not token.startswith("-") or name not in actions:
            overrides.append(token)
            continue
        flags.append(token)
        action = actions[name]
        if "=" in token or action.nargs == 0:
            continue
        takes_value = action.nargs is None or (
            action.nargs == "?"
            and i < len(tokens)
            and (action.choices is None or tokens[i] in action.choices)
        )
        if takes_value and i < len(tokens):
            flags.append(tokens[i])
            i += 1
    return flags, overrides


#: Hydra flags that show something instead of running a job.
_INFO_FLAGS = frozenset(
    {"--help", "-h", "--cfg", "-c", "--info", "-i", "--shell-completion", "-sc"}
)


def _informational(flags: Sequence[str]) -> bool:
    return any(f.split("=", 1)[0] in _INFO_FLAGS for f in flags)


def _failed_plugins(pm: PluginManager | None) -> str:
    if pm is None:
        return ""
    failed = [f"{p.name} ({p.error})" for p in pm.plugins() if p.status == "failed"]
    return f" [plugins that failed to load: {'; '.join(failed)}]" if failed else ""


def _one_line(exc: BaseException) -> str:
    r"""The error as one message: Hydra's lines joined, without its config search path.

    A :class:`SkelagnosticError` is kept whole: a line end in it comes from a
    name (a file, a joint, a value), and :func:`~skelagnostic.errors.error_line`
    shows it as ``\n``. A system error (errno set) names its file and cause.
    """
    # a system error (errno set); Hydra's MissingConfigException is an OSError without one
    if isinstance(exc, OSError) and exc.errno is not None:
        where = f" ({exc.filename})" if exc.filename else ""
        return f"cannot read or write a file{where}: {exc.strerror or exc}"
    if isinstance(exc, SkelagnosticError):
        text = str(exc)
    else:
        text = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        text = explain_shadowed_model(text.split(" Config search path:")[0])
    cause = exc.__cause__
    if isinstance(cause, OmegaConfBaseException) and str(cause).splitlines()[0] not in text:
        text += f" ({str(cause).splitlines()[0]})"
    return text


class _Job:
    """Hydra's task function for one command: runs the verb's task, keeps what the CLI reports.

    Failures are kept rather than raised inside Hydra, so that Hydra cleans up first;
    :func:`main` raises them again.

    Args:
        task: The verb.
        pm: The plugin manager.

    Attributes:
        saved: The config of the run ``ckpt_path=`` points into, if any.
        overrides: The user's overrides (they win over ``saved``).
    """

    def __init__(self, task: str, pm: PluginManager) -> None:
        self.task, self.pm = task, pm
        self.saved: DictConfig | None = None
        self.overrides: list[str] = []
        self.outer_argv = list(sys.argv)
        self.run_dirs: list[Path] = []
        self.results: list[tuple[Path, dict[str, float], Path | None]] = []
        self.failures: list[Exception] = []
        self.terminated = False

    def __call__(self, cfg: DictConfig) -> None:
        """Run the task of ``cfg`` (Hydra calls this once per job)."""
        from lightning.fabric.utilities.exceptions import MisconfigurationException
        from lightning.pytorch.utilities.exceptions import SIGTERMException

        from skelagnostic.cli.tasks import run

        self.run_dirs.append(Path(cfg.run_dir))
        if self.saved is not None:
            reuse_run_config(cfg, self.saved, self.overrides)
        # Lightning's DDP launcher re-executes sys.argv
        with _patched(self.outer_argv, {}), _job_log() as job_log:
            try:
                metrics = run(cfg, self.pm)
            except (SkelagnosticError, MisconfigurationException, HydraException) as exc:
                self.failures.append(exc)  # re-raised by main, after Hydra cleaned up
                return
            except SIGTERMException:  # a SystemExit with status 0: report it as a failure
                self.terminated = True
                return
            if getattr(metrics, "stopped", None):
                job_log.info("stopped: %s", metrics.stopped)  # type: ignore[attr-defined]
            job_log.info(
                "final metrics: %s",
                ", ".join(f"{k}={v:.5g}" for k, v in sorted(metrics.items())) or "none",
            )
            self.results.append((Path(cfg.run_dir), metrics, self._evaluated(cfg)))

    def _evaluated(self, cfg: DictConfig) -> Path | None:
        """The checkpoint file a validate, test or predict evaluated (for the summary)."""
        from skelagnostic.cli.tasks import CKPT_ALIASES, _preferred_checkpoint

        ckpt = cfg.ckpt_path
        if (
            not ckpt
            or self.task == "fit"
            or ckpt in CKPT_ALIASES
            or self.pm.checkpoint_reader_of(ckpt) is not None
        ):
            return None
        return checkpoint_of(ckpt, _preferred_checkpoint(cfg))


def _hydra_args(
    task: str, flags: list[str], overrides: list[str], pm: PluginManager, saved: DictConfig | None
) -> list[str]:
    """Hydra's command line: flags first, then ours and the user's overrides (user's last).

    Hydra's argparse takes its overrides as one run of positional arguments. Ours
    are the verb (``task=``), the model of the run or checkpoint ``ckpt_path=``
    names (unless the command line chooses one), and ``trainer.max_epochs=-1`` for
    a run sized in steps. The plugins' config trees come from the search-path
    plugin in ``hydra_plugins/skelagnostic_searchpath`` (so ``--help`` lists their
    options).
    """
    ours = [f"task={task}"]
    if _informational(flags) and not any(
        o.split("=", 1)[0].lstrip("+") in ("model", "experiment") for o in overrides
    ):
        ours.append("~model")  # --help / --cfg / --info work before a model is chosen
    external = pm.checkpoint_reader_of(value_of(overrides, "ckpt_path") or "")
    chosen = chosen_keys(overrides) & {"model", "experiment"}
    if saved is not None and not chosen:
        ours.append(f"model={saved.model.name}")  # the run's aligner, e.g. for test
    elif external is not None and not chosen:
        ours.append(f"model={external[0].model}")  # the model the reader builds
    ours += max_steps_overrides(overrides)
    if "--hydra-help" in flags:  # Hydra's own help: no app config, no overrides
        return list(flags)
    return [*flags, *ours, *overrides]


def _import_lightning_before_logging() -> None:
    """Import Lightning before Hydra configures logging, as a job will run.

    Lightning sets its loggers up when it is imported: while the root logger has no
    handler (before Hydra's job logging), ``lightning.pytorch`` and ``lightning.fabric``
    print through their own handler and do not propagate (what :func:`_job_log`
    expects). Imported later, inside the job, they would propagate to Hydra's handlers
    and print each line again on stdout and, prefixed ``INFO:``, on stderr.
    ``--help`` and the other informational flags do not call this: they need no
    Lightning.
    """
    import lightning  # noqa: F401


def _launch(task: str, args: Sequence[str], jobs: list[_Job]) -> int | None:
    """Compose and run the command with Hydra; the exit code when Hydra ends it by itself.

    Args:
        task: The verb.
        args: The user's arguments (without ``--debug``).
        jobs: Receives the :class:`_Job` as soon as the plugins are loaded (the error
            handler of :func:`main` reads its run directories and failed plugins).

    Returns:
        0 after ``--help`` and the like; ``None`` when the job ran (its results are
        in the job).
    """
    pm = get_plugin_manager()
    job = _Job(task, pm)
    jobs.append(job)
    register_model_configs(pm)
    flags, overrides = split_hydra_flags(args)
    overrides = [expand_home_in_override(o) for o in overrides]  # data.paths=[~/mocap]
    if not _informational(flags):  # Hydra would create an unusable run directory first
        from skelagnostic.cli.locations import check_run_locations

        check_run_locations(overrides)
        _import_lightning_before_logging()
    job.saved, job.overrides = run_of_overrides(overrides), overrides
    hydra_args = _hydra_args(task, flags, overrides, pm, job.saved)
    check_config_package()
    entry = hydra.main(
        config_path=f"pkg://{CONFIG_MODULE}", config_name="config", version_base="1.3"
    )(job)
    with _patched([job.outer_argv[0], *hydra_args], {"HYDRA_FULL_ERROR": "1"}), quiet_lightning():
        try:
            with _hidden_groups_in_help(flags):
                entry()
        except SystemExit as exc:  # Hydra exits by itself after --help and --hydra-help
            if exc.code not in (0, None) or job.failures or job.terminated or job.run_dirs:
                raise
            return 0
    return None


def _report(job: _Job, cpu_start: tuple[float, float]) -> int:
    """After Hydra: raise a job's failure, else print each run's table; the exit code."""
    if job.failures:
        raise job.failures[0]
    if job.terminated:
        kept = "".join(_discard_failed_run(d) for d in job.run_dirs)
        print(printable(f"skelagnostic {job.task}: terminated by SIGTERM{kept}"), file=sys.stderr)
        return SIGTERM_EXIT_CODE
    for run_dir, metrics, ckpt in job.results:  # evaluate printed its own table
        summary_table(
            job.task,
            run_dir,
            {} if job.task == "evaluate" else metrics,
            checkpoint=ckpt,
            stopped=getattr(metrics, "stopped", None),
        )
    if job.task == "fit":  # this command's CPU time, not the process's (tests, notebooks)
        (user, system), (user0, system0) = _cpu_times(), cpu_start
        if (hint := kernel_time_hint(user - user0, system - system0)) is not None:
            print(f"skelagnostic fit: hint: {hint}", file=sys.stderr)
    return 0


def main(task: str, argv: Sequence[str]) -> int:
    """Run one verb with Hydra command-line overrides.

    ``--debug`` (or ``SKELAGNOSTIC_DEBUG=1``) shows full tracebacks; otherwise
    configuration errors and :class:`~skelagnostic.errors.SkelagnosticError`
    print one line to stderr and return exit code 1. The line also names the
    plugins that failed to load, if any. A failed run's directory is deleted
    when it holds nothing but the resolved configs and logs; otherwise it is
    kept (and the line says where, with the checkpoint to resume from). A
    run stopped by SIGTERM returns :data:`SIGTERM_EXIT_CODE`.

    Args:
        task: One of :data:`~skelagnostic.cli.tasks.TASKS`.
        argv: The arguments after the verb.

    Returns:
        The exit code.
    """
    cpu_start = _cpu_times()
    args = [a for a in argv if a != "--debug"]
    debug = len(args) != len(argv) or os.environ.get(DEBUG_ENV, "") not in {"", "0"}
    jobs: list[_Job] = []
    try:
        code = _launch(task, args, jobs)
        return code if code is not None else _report(jobs[0], cpu_start)
    except BrokenPipeError:  # `| head` closed the output: skelagnostic.cli.main ends quietly
        raise
    except (
        SkelagnosticError,
        HydraException,
        OmegaConfBaseException,
        OSError,  # e.g. a full disk while Hydra writes the run folder's .hydra/ files
        *_lightning_errors(),
    ) as exc:
        kept = "".join(_discard_failed_run(d) for j in jobs for d in j.run_dirs)
        if debug:
            raise
        message = f"{_one_line(exc)}{_failed_plugins(jobs[0].pm if jobs else None)}{kept}"
        print(error_line(f"skelagnostic {task}", message), file=sys.stderr)
        return 1
    except Terminated:  # SIGTERM outside training (e.g. building the window cache)
        kept = "".join(_discard_failed_run(d) for j in jobs for d in j.run_dirs)
        print(printable(f"skelagnostic {task}: terminated by SIGTERM{kept}"), file=sys.stderr)
        return SIGTERM_EXIT_CODE
    except RunDirectoryRefused as exc:  # before Hydra wrote anything: nothing to discard
        if debug:
            raise
        print(error_line(f"skelagnostic {task}", exc), file=sys.stderr)
        return 1
    finally:
        release_run_directories()


def _lightning_errors() -> tuple[type[Exception], ...]:
    """Lightning's ``MisconfigurationException`` if Lightning is loaded, else nothing.

    A command that never loaded Lightning (``--help``, a bad override) cannot have
    raised it, so the CLI catches it without importing Lightning for that.
    """
    module = sys.modules.get("lightning.fabric.utilities.exceptions")
    return () if module is None else (module.MisconfigurationException,)


def evaluate(argv: Sequence[str]) -> int:
    """``skelagnostic evaluate ckpt_path=... [protocol=NAME] [overrides]``.

    ``--help`` lists the registered protocols before Hydra's help.
    """
    if any(a in ("--help", "-h") for a in argv):
        from skelagnostic.cli.plugins import protocols_text

        print(protocols_text(get_plugin_manager()))
    return main("evaluate", argv)


def _cpu_times() -> tuple[float, float]:
    """This process's user and system CPU time so far (seconds; zeros without ``resource``)."""
    try:
        import resource
    except ImportError:  # not POSIX
        return 0.0, 0.0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime, usage.ru_stime


def fit(argv: Sequence[str]) -> int:
    """``skelagnostic fit model=<name> [overrides]``: train."""
    return main("fit", argv)


def validate(argv: Sequence[str]) -> int:
    """``skelagnostic validate model=<name> ckpt_path=<ckpt> [overrides]``."""
    return main("validate", argv)


def test(argv: Sequence[str]) -> int:
    """``skelagnostic test model=<name> ckpt_path=<ckpt> [overrides]``."""
    return main("test", argv)


def predict(argv: Sequence[str]) -> int:
    """``skelagnostic predict model=<name> ckpt_path=<ckpt>``: latents to ``predictions.pt``."""
    return main("predict", argv)
