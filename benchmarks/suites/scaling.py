"""Suite ``scaling``: how each method's training scales with batch, threads, corpus and processes.

For each method (``vqpae``, ``humot``, ``pcmrl_recon``: PC-MRL stage 1,
``pcmrl_interp``: stage 2) the full Lightning training step
(:func:`benchmarks.suites.steptime.time_fit`: compute plus the data fetch
before it, median over the timed steps) on the first clips of the LaFAN1 corpus
(:func:`corpus`):

* **batch and threads**: windows/s at every batch size of :data:`SETTINGS` and
  1 and 2 torch threads (``<method>_windows_per_s_b<B>_t<T>``). The baseline of
  a 1-thread row is the smallest batch at 1 thread (batch scaling); of a
  2-thread row, the same batch at 1 thread (thread scaling).
* **corpus size**: peak RSS while training on 2, 5, 10 and 25 clips
  (``<method>_train_peak_rss_mib_<corpus>``: ``setup``, i.e. the streamed
  normalisation pass, and the timed steps, from a cache filled just before) and
  while filling the cache (``<method>_prepare_peak_rss_mib_<corpus>``), with the
  cache size (``<method>_cache_mib_<corpus>``) and the corpus's frames
  (``corpus_frames_<corpus>``). ``<corpus>`` is ``lafan1_<N>clips``, or
  ``generated_<N>clips`` when the LaFAN1 files are absent (procedural biped22
  walks of :data:`GENERATED_SECONDS`, each generated when the cache asks for it).
  Baseline: the smallest corpus of the same run, so a ratio near 1 means flat
  memory, the streaming datasets' claim.
* **DDP**: two CPU processes (Lightning's plain ``ddp`` strategy for every
  method, gloo, 1 thread each, the reference batch per process) against one
  process at the same batch with 1 thread (``<method>_ddp2_windows_per_s_b<B>``)
  and with 2 threads (``..._vs_t2``): the same two cores used by threads instead
  of processes.
* **GPU** (when torch sees one): the batch rows again in ``bf16-mixed``
  (``<method>_windows_per_s_b<B>_gpu_bf16``).
* **torch.compile** (``run.py --compile``): the reference batch with the
  networks of the training step compiled (:func:`compile_networks`), 1 CPU
  thread (and on the GPU in bf16-mixed), against the eager row of the same run
  (``..._compiled``); two more warm-up steps find and compile the networks. A method
  whose compilation fails has no compiled row (the error is printed), never an
  estimate.

Every measurement runs in its own process, forked from one child process that
imported torch, Lightning and the four plugins once (``base_rss_mib`` is that
process's RSS after the imports; a forked process shares those pages and counts
the ones it maps, so its peaks include most of them). Peak RSS is the process's high-water mark
(``VmHWM``; reset between filling the cache and training, ``/proc/self/clear_refs``).
The corpus root is ``run.py --data-root`` (``$SKELAGNOSTIC_BENCH_DATA``), else
``$SKELAGNOSTIC_DATA``, else ``../shared/datasets``; its ``lafan1/*.bvh`` files are
taken in name order. Sizes: ``smoke`` runs tiny networks (:data:`TINY`) on 1 and
2 clips to check the suite (tests), ``default`` and ``large`` the papers'
networks (``large``: more timed steps).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
import tempfile
import time
import traceback
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks.harness import (
    REPO_ROOT,
    Result,
    die_with_parent,
    peak_rss,
    retry_busy,
    run_child,
)

#: The methods, in report order.
METHODS = ("vqpae", "humot", "pcmrl_recon", "pcmrl_interp")
#: Environment variable holding the corpus root (``run.py --data-root``).
DATA_ENV = "SKELAGNOSTIC_BENCH_DATA"
#: Environment variable set by ``run.py --compile``: also time ``torch.compile``d models.
COMPILE_ENV = "SKELAGNOSTIC_BENCH_COMPILE"
#: Environment variable set by ``run.py --methods``: the methods to measure (comma-separated).
METHODS_ENV = "SKELAGNOSTIC_BENCH_METHODS"
#: Length of a generated clip (when the LaFAN1 files are absent), per size.
GENERATED_SECONDS = {"smoke": 10.0, "default": 150.0, "large": 150.0}
#: Tiny model options of the ``smoke`` size (as the DDP tests' runs).
TINY: dict[str, dict[str, Any]] = {
    "vqpae": {"num_codes": 8, "kernel_size": 7, "phase_kernel": 7, "pose_layers": 2},
    "humot": {"dim": 32, "latent": 16, "blocks": 1, "heads": 4, "kernel_size": 3},
    "pcmrl_recon": {
        "dim": 8,
        "stages": 2,
        "point_heads": 2,
        "temporal_dim": 16,
        "temporal_layers": 1,
        "temporal_heads": 2,
        "num_source_points": 64,
        "num_target_points": 128,
    },
    "pcmrl_interp": {"dim": 16, "heads": 2, "layers": 1, "ff_mult": 2, "max_relative": 16},
}


@dataclass(frozen=True)
class Settings:
    """What one size measures.

    Attributes:
        tiny: Tiny networks (:data:`TINY`) instead of the papers'.
        batches: Batch sizes per method (windows per dataset per step); the
            reference batch (DDP, compile, memory) is the last but one, else the only one.
        threads: Torch thread counts of the batch rows.
        corpus: Corpus sizes (clips) of the memory rows.
        steps: Timed steps per measurement.
        warmup: Untimed steps first.
    """

    tiny: bool
    batches: dict[str, tuple[int, ...]]
    threads: tuple[int, ...]
    corpus: tuple[int, ...]
    steps: int
    warmup: int

    def reference(self, method: str) -> int:
        """The batch of the DDP, compile and memory rows of ``method``."""
        batches = self.batches[method]
        return batches[-2] if len(batches) > 1 else batches[0]


_PAPER_BATCHES = {
    "vqpae": (16, 32, 64, 128),
    "humot": (8, 16, 32, 64),
    "pcmrl_recon": (4, 8, 16, 32),
    "pcmrl_interp": (4, 8, 16, 32),
}
SETTINGS: dict[str, Settings] = {
    "smoke": Settings(True, dict.fromkeys(METHODS, (2, 4)), (1, 2), (1, 2), steps=2, warmup=1),
    "default": Settings(False, _PAPER_BATCHES, (1, 2), (2, 5, 10, 25), steps=3, warmup=1),
    "large": Settings(False, _PAPER_BATCHES, (1, 2), (2, 5, 10, 25), steps=10, warmup=2),
}


# ----------------------------------------------------------------------------- corpus
def corpus_root() -> Path:
    """``$SKELAGNOSTIC_BENCH_DATA``, else ``$SKELAGNOSTIC_DATA``, else ``../shared/datasets``."""
    for env in (DATA_ENV, "SKELAGNOSTIC_DATA"):
        if os.environ.get(env):
            return Path(os.environ[env]).expanduser()
    return REPO_ROOT.parent / "shared" / "datasets"


def corpus(num_clips: int, root: Path | None = None) -> tuple[str, list[str]] | None:
    """The first ``num_clips`` LaFAN1 files (name order) under ``root``/lafan1.

    Returns:
        ``("lafan1_<N>clips", paths)``, or ``None`` when the folder holds fewer files.
    """
    folder = (root if root is not None else corpus_root()) / "lafan1"
    files = sorted(folder.glob("*.bvh")) if folder.is_dir() else []
    if len(files) < num_clips:
        return None
    return f"lafan1_{num_clips}clips", [str(f) for f in files[:num_clips]]


def corpus_label(num_clips: int, files: list[str] | None) -> str:
    """``lafan1_<N>clips`` for real files, ``generated_<N>clips`` otherwise."""
    return f"{'lafan1' if files else 'generated'}_{num_clips}clips"


def source(num_clips: int, files: list[str] | None, size: str) -> Any:
    """The clip source of a corpus: LaFAN1 ``files``, or generated walks when ``None``."""
    from skelagnostic.data import BVHSource

    if files:
        return BVHSource(files, units="cm", name="lafan1")
    from benchmarks.suites.bigdata import generated_walks

    frames = round(GENERATED_SECONDS[size] * 30) + 1
    return generated_walks(num_clips, frames, name="generated")


# ----------------------------------------------------------------------------- methods
def build(method: str, tiny: bool, clips: Any, batch: int, cache_dir: str) -> tuple[Any, Any, int]:
    """The model (seed 0), its data module on ``clips`` and the windows of one step.

    The papers' settings as in the ``training`` suite's parts (VQ-PAE at the
    authors' ``train_vq.py`` options and 60 fps, HuMoT's 30-frame chunks, PC-MRL
    stage 1 onto the procedural CMU-31 skeleton, stage 2's 128-frame windows);
    ``tiny`` swaps in :data:`TINY` and shorter windows. Every clip trains
    (``val_fraction=0``).
    """
    import torch

    torch.manual_seed(0)
    options = TINY[method] if tiny else {}
    common = {"batch_size": batch, "val_fraction": 0.0, "cache_dir": cache_dir}
    if method == "vqpae":
        from skelagnostic_vqpae.aligner import VqpaeAligner
        from skelagnostic_vqpae.data import VqpaeDataModule

        from benchmarks.suites.training_vqpae import AUTHORS_OPTIONS

        dm: Any = VqpaeDataModule(clips, fps=30 if tiny else 60, stride=1, **common)
        model: Any = VqpaeAligner(**{**AUTHORS_OPTIONS, **options})
    elif method == "humot":
        from skelagnostic_humot import HumotAligner, HumotDataModule

        dm = HumotDataModule([clips], **common)
        model = HumotAligner(**options)
    elif method == "pcmrl_recon":
        from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
        from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule

        window = 16 if tiny else 64
        dm = PcmrlReconDataModule(
            clips, target="biped31", fps=30.0, window=window, stride=16, **common
        )
        model = PcmrlReconAligner(**options)
    elif method == "pcmrl_interp":
        from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
        from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule

        window = 32 if tiny else 128
        dm = PcmrlInterpDataModule(clips, fps=30.0, window=window, **common)
        model = PcmrlInterpAligner(window=window, **options)
    else:
        raise ValueError(f"scaling: unknown method {method!r}; known: {', '.join(METHODS)}")
    return model, dm, batch


def outermost(called: list[str]) -> list[str]:
    """The names of ``called`` (dotted module paths) that no other name of it contains."""
    names = set(called)
    return sorted(
        n for n in names if not any(n.startswith(other + ".") for other in names if other != n)
    )


def compile_networks() -> Any:
    """A Lightning callback compiling, in place, the networks a training step calls.

    During the first training step it records every sub-module called through
    ``__call__``; at its end it compiles the outermost of them
    (``nn.Module.compile``), so the next step compiles them. It finds the
    networks whatever the method's layout: VQ-PAE builds its per-character
    networks in ``setup`` and calls them from a ``ModuleList``, and Lightning
    calls ``training_step`` directly, so compiling the LightningModule itself
    would change nothing (and compiling ``training_step`` fails in Lightning's
    logging). Losses computed outside the networks stay eager.
    """
    import lightning as L

    class CompileNetworks(L.Callback):
        def __init__(self) -> None:
            self.called: list[str] = []
            self.hooks: list[Any] = []

        def on_fit_start(self, trainer: Any, pl_module: Any) -> None:
            for name, module in pl_module.named_modules():
                if name:
                    self.hooks.append(
                        module.register_forward_pre_hook(lambda *_, n=name: self.called.append(n))
                    )

        def on_train_batch_end(self, trainer: Any, pl_module: Any, *args: Any) -> None:
            if not self.hooks:
                return
            for hook in self.hooks:
                hook.remove()
            self.hooks = []
            for name in outermost(self.called):
                pl_module.get_submodule(name).compile()

    return CompileNetworks()


# ----------------------------------------------------------------------------- forking
def _status_kib(field: str) -> int | None:
    status = Path("/proc/self/status")
    if not status.exists():
        return None
    for line in status.read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return None


def _reset_peak() -> bool:
    """Reset this process's RSS high-water mark (Linux ``clear_refs``); False if unsupported."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


def forked(
    fn: Callable[..., Any], *args: Any, env: dict[str, str] | None = None
) -> tuple[int, Path]:
    """Start ``fn(*args)`` in a forked process (with ``env`` added to its environment).

    The child writes ``{"result": ..., "peak_rss_mib": ...}``, or ``{"error": traceback}``,
    as JSON to a file in the temporary directory, which exists only once it is complete
    (written under another name, then renamed); :func:`collect` deletes it. The child
    dies with this process (:func:`~benchmarks.harness.die_with_parent`), so a killed
    benchmark leaves no file behind (unless killed between a child's last write and
    its collection).

    Returns:
        ``(pid, path of that file)``, for :func:`collect`.
    """
    parent = os.getpid()
    name = Path(tempfile.gettempdir()) / f"skelagnostic-scaling-{parent}-{uuid.uuid4().hex}.json"
    sys.stdout.flush()
    sys.stderr.flush()
    pid = retry_busy(os.fork, "a measuring process")
    if pid:
        return pid, name
    die_with_parent(parent)
    code = 1
    try:
        os.environ.update(env or {})
        payload: dict[str, Any] = {"result": fn(*args), "peak_rss_mib": peak_rss()}
        code = 0
    except BaseException:
        payload = {"error": traceback.format_exc()}
    try:
        partial = name.with_name(f"{name.name}.{os.getpid()}.part")
        partial.write_text(json.dumps(payload))
        partial.replace(name)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _payload(path: Path, what: str) -> tuple[Any, float]:
    """The ``(result, peak RSS)`` a finished child of :func:`forked` wrote to ``path``."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        text = ""
    finally:
        path.unlink(missing_ok=True)
        for partial in path.parent.glob(f"{path.name}.*.part"):  # a child killed mid-write
            partial.unlink(missing_ok=True)
    if not text:
        raise RuntimeError(f"scaling: {what}: the measuring process died without a result")
    payload = json.loads(text)
    if "error" in payload:
        raise RuntimeError(f"scaling: {what} failed:\n{payload['error']}")
    return payload["result"], payload["peak_rss_mib"]


def collect(child: tuple[int, Path], what: str) -> tuple[Any, float]:
    """Wait for a child of :func:`forked`: its ``(result, peak RSS in MiB)``.

    Raises:
        RuntimeError: The child failed (its traceback is in the message) or died.
    """
    os.waitpid(child[0], 0)
    return _payload(child[1], what)


def collect_all(children: list[tuple[int, Path]], what: str) -> list[tuple[Any, float]]:
    """Wait for children that work together (DDP ranks); the first failure kills the others.

    Raises:
        RuntimeError: A child failed (the first to fail is reported) or died.
    """
    pending = dict(enumerate(children))
    while pending:
        for i, (pid, path) in list(pending.items()):
            done, status = os.waitpid(pid, os.WNOHANG)
            if not done:
                continue
            del pending[i]
            if status != 0:
                for other, other_path in pending.values():
                    os.kill(other, signal.SIGKILL)
                    os.waitpid(other, 0)
                    other_path.unlink(missing_ok=True)
                _payload(path, f"{what} {i}")  # raises with the child's traceback
                raise RuntimeError(f"scaling: {what} {i} exited with status {status}")
        time.sleep(0.05)
    return [_payload(path, f"{what} {i}") for i, (_, path) in enumerate(children)]


def in_fork(fn: Callable[..., Any], *args: Any, what: str) -> tuple[Any, float]:
    """Run ``fn(*args)`` in a forked process: its ``(result, peak RSS in MiB)``."""
    return collect(forked(fn, *args), what)


# ----------------------------------------------------------------------------- measurements
@dataclass(frozen=True)
class Job:
    """One training measurement: a method on a corpus at a batch size.

    Attributes:
        method: A key of :data:`METHODS`.
        size: The suite size (settings, generated clip length).
        num_clips: Clips of the corpus.
        files: LaFAN1 files, or ``None`` for generated clips.
        batch: Windows per dataset per step.
        cache_dir: Window cache of this corpus.
    """

    method: str
    size: str
    num_clips: int
    files: list[str] | None
    batch: int
    cache_dir: str

    def setup(self) -> tuple[Any, Any, int]:
        """Model, data module and windows per step (:func:`build`)."""
        clips = source(self.num_clips, self.files, self.size)
        return build(self.method, SETTINGS[self.size].tiny, clips, self.batch, self.cache_dir)


def _timed(
    job: Job, threads: int, ranks: int = 1, extra_warmup: int = 0, **options: Any
) -> dict[str, float]:
    """Time ``job``'s training steps with ``threads`` torch threads (in a forked child).

    Args:
        job: The measurement.
        threads: Torch threads.
        ranks: DDP processes the step's windows are counted over.
        extra_warmup: Untimed steps added to the size's warm-up.
        **options: More arguments of :func:`~benchmarks.suites.steptime.time_fit`.

    Returns:
        :func:`~benchmarks.suites.steptime.time_fit`'s figures and ``windows_per_s``.
    """
    import lightning as L
    import torch

    from benchmarks.suites.steptime import time_fit

    torch.set_num_threads(threads)
    model, dm, windows = job.setup()
    L.seed_everything(0, verbose=False)
    settings = SETTINGS[job.size]
    timing = time_fit(model, dm, settings.steps, settings.warmup + extra_warmup, **options)
    return {**timing, "windows_per_s": ranks * windows / timing["median_step_s"]}


def throughput(
    job: Job,
    threads: int,
    accelerator: str = "cpu",
    precision: str | None = None,
    compiled: bool = False,
) -> dict[str, float]:
    """Windows/s of ``job`` with ``threads`` torch threads (a forked child).

    Compiled: one more warm-up step finds the networks, the next compiles them.
    """
    return _timed(
        job,
        threads,
        extra_warmup=2 if compiled else 0,
        accelerator=accelerator,
        precision=precision,
        callbacks=[compile_networks()] if compiled else [],
    )


def ddp_rank(job: Job) -> dict[str, float]:
    """One of two DDP ranks (plain ``ddp``, gloo, 1 thread): windows/s of both ranks together.

    Every method runs under Lightning's plain ``ddp`` strategy: each trainable
    parameter gets a gradient at every step, so DDP need not search for unused ones.
    """
    return _timed(job, 1, ranks=2, accelerator="cpu", devices=2, strategy="ddp")


def memory(job: Job, threads: int) -> dict[str, float | None]:
    """Peak RSS filling the cache, then training (``setup`` and 2 steps) from it."""
    import lightning as L
    import torch

    from benchmarks.suites.steptime import time_fit

    torch.set_num_threads(threads)
    model, dm, _ = job.setup()
    dm.prepare_data()
    prepare = _status_kib("VmHWM")
    train = None
    if _reset_peak():
        L.seed_everything(0, verbose=False)
        time_fit(model, dm, steps=1, warmup=1)
        train = _status_kib("VmHWM")
    cache = sum(p.stat().st_size for p in Path(job.cache_dir).rglob("*") if p.is_file())
    return {
        "prepare_peak_mib": None if prepare is None else prepare / 1024,
        "train_peak_mib": None if train is None else train / 1024,
        "cache_mib": cache / 2**20,
    }


def bvh_frames(path: str) -> int:
    """The ``Frames:`` count of a BVH file's header."""
    with open(path) as fh:
        for line in fh:
            if line.strip().startswith("Frames:"):
                return int(line.split(":", 1)[1])
    raise ValueError(f"{path}: no 'Frames:' line")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _ddp(job: Job) -> dict[str, float]:
    """Both ranks of a 2-process DDP run, forked together; rank 0's figures."""
    env = {
        "MASTER_ADDR": "127.0.0.1",
        "MASTER_PORT": str(_free_port()),
        "WORLD_SIZE": "2",
        "NODE_RANK": "0",
    }
    children = [forked(ddp_rank, job, env={**env, "LOCAL_RANK": str(r)}) for r in (0, 1)]
    return collect_all(children, f"{job.method} DDP rank")[0][0]


def _import_everything() -> None:
    """Import torch, Lightning and the four plugins (before forking: every child shares them)."""
    for plugin in ("vqpae", "humot", "pcmrl"):
        path = str(REPO_ROOT / "plugins" / plugin / "src")
        if path not in sys.path:
            sys.path.insert(0, path)
    import lightning  # noqa: F401
    import skelagnostic_humot  # noqa: F401
    import skelagnostic_pcmrl.interp.aligner
    import skelagnostic_pcmrl.recon.aligner  # noqa: F401
    import skelagnostic_vqpae.aligner  # noqa: F401
    import torch  # noqa: F401

    import skelagnostic.data  # noqa: F401


def selected_methods(names: str | None = None) -> tuple[str, ...]:
    """The methods to measure: ``names`` (comma-separated; default ``$METHODS_ENV``), else all.

    Kept in the order of :data:`METHODS`.

    Raises:
        ValueError: A name that is not one of :data:`METHODS`.
    """
    names = os.environ.get(METHODS_ENV) if names is None else names
    if not names:
        return METHODS
    chosen = {n.strip() for n in names.split(",") if n.strip()}
    unknown = sorted(chosen - set(METHODS))
    if unknown or not chosen:
        raise ValueError(
            f"scaling: unknown method(s) {', '.join(unknown) or repr(names)}; "
            f"known: {', '.join(METHODS)}"
        )
    return tuple(m for m in METHODS if m in chosen)


def measure_all(size: str, compiled: bool = False) -> dict[str, Any]:
    """Child process: every measurement of ``size``, each in a process forked from this one.

    Returns:
        Raw figures, turned into results by :func:`results`.
    """
    from benchmarks.suites.steptime import accelerators

    if not hasattr(os, "fork"):
        raise RuntimeError("the scaling suite forks its measuring processes (POSIX only)")
    _import_everything()
    settings = SETTINGS[size]
    threads = settings.threads
    devices = accelerators()
    raw: dict[str, Any] = {
        "base_rss_mib": None if (rss := _status_kib("VmRSS")) is None else rss / 1024,
        "devices": devices,
        "corpus_frames": {},
        "methods": {},
    }
    found = {n: corpus(n) for n in settings.corpus}
    sizes = [n for n in settings.corpus if found[n]] or list(settings.corpus)
    if len(sizes) < len(settings.corpus) and any(found.values()):
        print(
            f"scaling: {corpus_root() / 'lafan1'} holds fewer than {max(settings.corpus)} "
            f"clips: no rows for {sorted(set(settings.corpus) - set(sizes))} clips",
            file=sys.stderr,
        )
    corpora = {n: found[n][1] if found[n] else None for n in sizes}
    for n in sizes:
        files = corpora[n]
        raw["corpus_frames"][corpus_label(n, files)] = (
            sum(bvh_frames(f) for f in files)
            if files
            else n * (round(GENERATED_SECONDS[size] * 30) + 1)
        )
    small = sizes[0]
    with tempfile.TemporaryDirectory(prefix="skelagnostic-scaling-") as tmp:
        for method in selected_methods():
            cache = str(Path(tmp) / method / "curves")
            ref = settings.reference(method)
            out: dict[str, Any] = {"cpu": {}, "gpu_bf16": {}, "compiled": {}, "memory": {}}

            def job(batch: int, n: int = small, cache_dir: str = cache, m: str = method) -> Job:
                return Job(m, size, n, corpora[n], batch, cache_dir)

            for t in threads:
                for b in settings.batches[method]:
                    got, _ = in_fork(throughput, job(b), t, what=f"{method} batch {b} x{t}")
                    out["cpu"][f"b{b}_t{t}"] = got["windows_per_s"]
            if "gpu" in devices:
                for b in settings.batches[method]:
                    got, _ = in_fork(
                        throughput,
                        job(b),
                        max(threads),
                        "gpu",
                        "bf16-mixed",
                        what=f"{method} batch {b} gpu",
                    )
                    out["gpu_bf16"][f"b{b}"] = got["windows_per_s"]
            if compiled:
                for device, key, precision in (
                    ("cpu", f"b{ref}_t1", None),
                    ("gpu", f"b{ref}_gpu_bf16", "bf16-mixed"),
                ):
                    if device not in devices:
                        continue
                    try:
                        got, _ = in_fork(
                            throughput,
                            job(ref),
                            1,
                            device,
                            precision,
                            True,
                            what=f"{method} compiled ({device})",
                        )
                    except RuntimeError as err:  # reported, and the row stays absent
                        print(err, file=sys.stderr)
                        continue
                    out["compiled"][key] = got["windows_per_s"]
            out["ddp2"] = _ddp(job(ref))["windows_per_s"]
            for n in sizes:
                label = corpus_label(n, corpora[n])
                fresh = str(Path(tmp) / method / label)
                got, _ = in_fork(memory, job(ref, n, fresh), 1, what=f"{method} memory {label}")
                out["memory"][label] = got
            raw["methods"][method] = out
    return raw


# ----------------------------------------------------------------------------- results
def _threads(t: int) -> str:
    return f"{t} thread{'s' if t > 1 else ''}"


def results(raw: dict[str, Any], size: str) -> list[Result]:
    """The suite's results from the raw figures of :func:`measure_all` (see the module doc)."""
    settings = SETTINGS[size]
    t1 = settings.threads[0]
    out = []
    if raw["base_rss_mib"] is not None:  # Linux only (/proc)
        out.append(Result("base_rss_mib", "MiB", raw["base_rss_mib"]))
    out += [
        Result(f"corpus_frames_{label}", "frames", float(frames), higher_is_better=True)
        for label, frames in raw["corpus_frames"].items()
    ]
    labels = list(raw["corpus_frames"])
    for method in (m for m in METHODS if m in raw["methods"]):  # run.py --methods: a subset
        got = raw["methods"][method]
        batches, ref = settings.batches[method], settings.reference(method)
        cpu, small = got["cpu"], batches[0]
        for t in settings.threads:
            for b in batches:
                if t == t1:
                    base = (
                        None
                        if b == small
                        else (f"batch {small}, {_threads(t)} (same run)", cpu[f"b{small}_t{t}"])
                    )
                else:
                    base = (f"batch {b}, {_threads(t1)} (same run)", cpu[f"b{b}_t{t1}"])
                out.append(_rate(f"{method}_windows_per_s_b{b}_t{t}", cpu[f"b{b}_t{t}"], base))
        gpu = got["gpu_bf16"]
        for b in batches:
            if f"b{b}" in gpu:
                base = (
                    None
                    if b == small
                    else (f"batch {small}, gpu bf16-mixed (same run)", gpu[f"b{small}"])
                )
                out.append(_rate(f"{method}_windows_per_s_b{b}_gpu_bf16", gpu[f"b{b}"], base))
        for key, value in got["compiled"].items():
            eager = cpu[key] if key in cpu else gpu[key.removesuffix("_gpu_bf16")]
            out.append(
                _rate(
                    f"{method}_windows_per_s_{key}_compiled",
                    value,
                    ("eager, same batch and device (same run)", eager),
                )
            )
        one = f"1 process x {_threads(t1)}, batch {ref} (same run)"
        out.append(
            _rate(f"{method}_ddp2_windows_per_s_b{ref}", got["ddp2"], (one, cpu[f"b{ref}_t{t1}"]))
        )
        t_max = max(settings.threads)
        if t_max > t1:
            out.append(
                _rate(
                    f"{method}_ddp2_windows_per_s_b{ref}_vs_t{t_max}",
                    got["ddp2"],
                    (
                        f"1 process x {_threads(t_max)}, batch {ref} (same run)",
                        cpu[f"b{ref}_t{t_max}"],
                    ),
                )
            )
        memory = got["memory"]
        first = memory[labels[0]]
        for label in labels:
            row = memory[label]
            for key, figure in (
                ("train_peak_mib", "train_peak_rss_mib"),
                ("prepare_peak_mib", "prepare_peak_rss_mib"),
            ):
                if row[key] is None:
                    continue
                baseline = None if label == labels[0] else labels[0]
                out.append(
                    Result(
                        f"{method}_{figure}_{label}",
                        "MiB",
                        row[key],
                        baseline and f"{baseline} (same run)",
                        baseline and first[key],
                    )
                )
            out.append(Result(f"{method}_cache_mib_{label}", "MiB", row["cache_mib"]))
    return out


def _rate(name: str, value: float, base: tuple[str, float] | None) -> Result:
    if base is None:
        return Result(name, "windows/s", value, higher_is_better=True)
    return Result(name, "windows/s", value, base[0], base[1], higher_is_better=True)


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` (one child process that forks every measurement)."""
    selected_methods()  # an unknown --methods name fails before the child starts
    raw, _ = run_child(
        "benchmarks.suites.scaling:measure_all",
        size=size,
        compiled=os.environ.get(COMPILE_ENV) == "1",
    )
    return results(raw, size)


# ----------------------------------------------------------------------------- figure
def _figures(report: dict[str, Any]) -> dict[str, float]:
    """``{result name: value}`` of a report, without the ``scaling/`` prefix of ``--suite all``."""
    return {
        r["name"].removeprefix("scaling/"): r["value"]
        for r in report["results"]
        if report["suite"] == "scaling" or r["name"].startswith("scaling/")
    }


def _series(values: dict[str, float], pattern: str) -> list[tuple[int, float]]:
    """``(number, value)`` of the names matching ``pattern`` (one ``(\\d+)`` group), sorted."""
    import re

    regex = re.compile(pattern)
    found = [(int(m.group(1)), v) for k, v in values.items() if (m := regex.fullmatch(k))]
    return sorted(found)


def plot(
    report: dict[str, Any], out_dir: Path, date: str | None = None, size: str | None = None
) -> list[Path]:
    """Draw the scaling figure of a report (``scaling.png`` in ``out_dir``).

    Panels: windows/s against batch size (1 thread solid, 2 threads dashed, GPU
    bf16-mixed dotted), peak RSS against the corpus's frames (training solid,
    filling the cache dashed), and the speedups of 2 threads and of 2 DDP
    processes over 1 process with 1 thread at the reference batch.

    Args:
        report: A ``run.py --json`` report of the ``scaling`` suite (or ``all``).
        out_dir: Folder of the PNG (created).
        date: Date of the run, shown in the title.
        size: The run's ``--size``, shown in the title.

    Returns:
        The written files.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    values = _figures(report)
    if not values:
        return []
    machine = report["machine"]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    colors = dict(zip(METHODS, ("C0", "C1", "C2", "C3"), strict=True))
    frames = dict(_series_labels(values))
    for method in METHODS:
        color = colors[method]
        for style, suffix, what in (
            ("-", "_t1", "1 thread"),
            ("--", "_t2", "2 threads"),
            (":", "_gpu_bf16", "gpu bf16"),
        ):
            points = _series(values, rf"{method}_windows_per_s_b(\d+){suffix}")
            if points:
                _line(axes[0], points, style, color, f"{method} {what}")
        for style, kind in (("-", "train"), ("--", "prepare")):
            points = sorted(
                (frames[label], v)
                for label in frames
                if (v := values.get(f"{method}_{kind}_peak_rss_mib_{label}")) is not None
            )
            if points:
                _line(axes[1], points, style, color, f"{method} {kind}")
    axes[0].set_xscale("log", base=2)
    axes[0].set(
        yscale="log",
        xlabel="batch (windows per dataset)",
        ylabel="windows/s",
        title="throughput against batch",
    )
    axes[1].set_xscale("log")
    axes[1].set(
        xlabel="corpus frames",
        ylabel="peak RSS (MiB)",
        title="memory against corpus size",
    )
    axes[1].set_ylim(bottom=0)
    bars = []
    for method in METHODS:
        ddp = _series(values, rf"{method}_ddp2_windows_per_s_b(\d+)")
        one = ddp and values.get(f"{method}_windows_per_s_b{ddp[0][0]}_t1")
        if ddp and one:
            two = values.get(f"{method}_windows_per_s_b{ddp[0][0]}_t2")
            bars.append((method, None if two is None else two / one, ddp[0][1] / one))
    for i, (method, threads, ddp) in enumerate(bars):
        if threads is not None:
            axes[2].bar(
                i - 0.2,
                threads,
                0.4,
                color=colors[method],
                alpha=0.5,
                label="2 threads" if i == 0 else None,
            )
        axes[2].bar(
            i + 0.2, ddp, 0.4, color=colors[method], label="2 DDP processes" if i == 0 else None
        )
    axes[2].axhline(1.0, color="k", lw=0.8)
    axes[2].set_xticks(range(len(bars)), [b[0] for b in bars])
    axes[2].set(ylabel="x 1 process, 1 thread", title="2 cores: threads or DDP")
    for ax in axes[:2]:
        low, high = ax.get_xlim()
        ax.xaxis.set_major_formatter(ScalarFormatter())
        # minor ticks get labels only within one decade (else they run into each other)
        wide = low > 0 and high / low > 10
        ax.xaxis.set_minor_formatter(NullFormatter() if wide else ScalarFormatter())
        ax.legend(fontsize=6, ncol=2)
    axes[2].legend(fontsize=7)
    for ax in axes:
        ax.grid(alpha=0.3)
    load = machine.get("load_average_start"), machine.get("load_average_end")
    fig.suptitle(
        f"scaling suite{f' --size {size}' if size else ''}{f', {date}' if date else ''}: "
        f"{machine['cpu_count']} CPUs "
        f"({machine['processor']}), {machine['ram_gib']} GiB"
        + (f", load average {load[0]:g} -> {load[1]:g}" if None not in load else ""),
        fontsize=9,
    )
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "scaling.png"
    fig.savefig(path, dpi=80, metadata={"Software": None})
    plt.close(fig)
    return [path]


def _line(ax: Any, points: list[tuple[float, float]], style: str, color: str, label: str) -> None:
    """Draw ``points`` as one marked line of ``ax``."""
    ax.plot(*zip(*points, strict=True), style, color=color, marker="o", label=label)


def _series_labels(values: dict[str, float]) -> list[tuple[str, float]]:
    """``(corpus label, frames)`` of the report's ``corpus_frames_<label>`` figures."""
    return [
        (k.removeprefix("corpus_frames_"), v)
        for k, v in values.items()
        if k.startswith("corpus_frames_")
    ]


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.suites.scaling REPORT.json OUT_DIR [--date D] [--size S]``: redraw."""
    import argparse

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("report", type=Path)
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--date", default=None, help="date of the run, for the title")
    parser.add_argument("--size", default=None, help="the run's --size, for the title")
    args = parser.parse_args(argv)
    for path in plot(json.loads(args.report.read_text()), args.out_dir, args.date, args.size):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
