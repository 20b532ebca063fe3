"""Optimizers and learning-rate schedules from config: ``model.optimizer``, ``model.scheduler``.

Every built-in aligner takes its optimizer and its schedule as two constructor
arguments written the way `lightning-hydra-template
<https://github.com/ashleve/lightning-hydra-template>`_ writes them, a
``_partial_`` node each::

    model:
      optimizer:
        _target_: torch.optim.Adam
        _partial_: true
        lr: 1.0e-05
        betas: [0.9, 0.999]
      scheduler:
        _target_: skelagnostic.aligners.optim.cyclic_lr
        _partial_: true
        max_lr: 1.0e-04
        period_epochs: 10.0

so ``model.optimizer.lr`` is the optimizer's initial learning rate in every
aligner, and another optimizer is one override away
(``model.optimizer._target_=torch.optim.AdamW``). A spec is either such a
mapping (``_target_``: the dotted path of a callable; the other keys but
``_partial_``: its keyword arguments) or a callable, e.g. a
:func:`functools.partial`. ``_partial_`` must be true or absent: an optimizer
needs the parameters and a schedule its optimizer, which exist only when
training starts, so both are always called later with them.

A schedule is called with the optimizer and, when its signature names them,
the run's quantities, which a config cannot know:

* ``steps_per_epoch``: optimizer steps per training epoch
  (:func:`~skelagnostic.aligners.steps_per_epoch`), for periods in epochs;
* ``total_steps``: the trainer's ``estimated_stepping_batches``;
* ``trainer``: the Lightning trainer itself (a plugin's schedule that needs more).

Hydra's ``instantiate`` would do the resolving, but aligners must run without
Hydra (only the command line imports it), so the few lines it takes live here:
:func:`resolve` imports the target, and the keyword arguments are checked
against its signature when the aligner is built, so a misspelt key fails before
any training with the key named.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import torch

from skelagnostic.errors import SkelagnosticError

__all__ = [
    "RUN_QUANTITIES",
    "OptimizerSpec",
    "check_specs",
    "configure_optimization",
    "cosine_lr",
    "cyclic_lr",
    "linear_warmup",
    "resolve",
    "spec_dict",
]

#: A ``_partial_`` node (a mapping with ``_target_``) or a callable.
OptimizerSpec = Mapping[str, Any] | Callable[..., Any]

#: The run quantities a schedule receives when its signature names them.
RUN_QUANTITIES = ("steps_per_epoch", "total_steps", "trainer")


def resolve(spec: OptimizerSpec, field: str, first: str) -> Callable[..., Any]:
    """The callable of ``spec`` with its keyword arguments bound, checked against its signature.

    Args:
        spec: A mapping with ``_target_`` (and ``_partial_`` true or absent) or a callable.
        field: Where the spec comes from, for messages (``"model.optimizer"``).
        first: The name of the argument the caller passes positionally later
            (``"params"``, ``"optimizer"``): it must not be among the keys.

    Returns:
        A callable (a :func:`functools.partial` for a mapping).

    Raises:
        SkelagnosticError: The target cannot be imported, ``_partial_`` is false, or
            a key is not an argument of the target (each names ``field.<key>``).

    Examples:
        >>> make = resolve({"_target_": "torch.optim.SGD", "lr": 0.1}, "model.optimizer", "params")
        >>> make([torch.zeros(1, requires_grad=True)]).defaults["lr"]
        0.1
        >>> resolve({"_target_": "torch.optim.SGD", "lrr": 0.1}, "model.optimizer", "params")
        Traceback (most recent call last):
        ...
        skelagnostic.errors.SkelagnosticError: model.optimizer.lrr is not an argument of \
torch.optim.SGD; accepted: dampening, differentiable, foreach, fused, lr, maximize, \
momentum, nesterov, weight_decay
    """
    if callable(spec):
        return spec
    if not isinstance(spec, Mapping) or "_target_" not in spec:
        raise SkelagnosticError(
            f"{field} must be a mapping with _target_ (e.g. {{_target_: torch.optim.Adam, "
            f"_partial_: true, lr: 1.0e-4}}) or a callable, got {spec!r}"
        )
    if spec.get("_partial_", True) is not True:
        raise SkelagnosticError(
            f"{field}._partial_={spec['_partial_']!r}: it must be true (the {first} exist "
            "only when training starts)"
        )
    target = _locate(str(spec["_target_"]), f"{field}._target_")
    kwargs = {k: v for k, v in spec.items() if k not in ("_target_", "_partial_")}
    _check_arguments(target, str(spec["_target_"]), kwargs, field)
    return functools.partial(target, **kwargs)


def spec_dict(spec: OptimizerSpec | None) -> Any:
    """A plain ``dict`` copy of a mapping spec (tuples as lists, as YAML has them); else ``spec``.

    Hyper-parameters hold the copy: a checkpoint and ``hparams.yaml`` store it as plain data.
    """
    if spec is None or callable(spec) or not isinstance(spec, Mapping):
        return spec
    return {k: list(v) if isinstance(v, tuple) else v for k, v in spec.items()}


def check_specs(optimizer: OptimizerSpec, scheduler: OptimizerSpec | None) -> tuple[Any, Any]:
    """``model.optimizer`` and ``model.scheduler`` as plain copies, checked: for a constructor.

    Checking when the aligner is built makes a wrong target or key fail before
    any data is read, with the key named (:func:`resolve`).

    Args:
        optimizer: The optimizer spec.
        scheduler: The schedule spec or ``None``.

    Returns:
        ``(optimizer, scheduler)`` as :func:`spec_dict` copies.
    """
    optimizer, scheduler = spec_dict(optimizer), spec_dict(scheduler)
    resolve(optimizer, "model.optimizer", "params")
    if scheduler is not None:
        resolve(scheduler, "model.scheduler", "optimizer")
    return optimizer, scheduler


def configure_optimization(
    optimizer: OptimizerSpec,
    scheduler: OptimizerSpec | None,
    params: Iterable[Any],
    trainer: Any = None,
    interval: str = "step",
    prefer: Mapping[str, Any] | None = None,
) -> Any:
    """What ``configure_optimizers`` returns: the optimizer and, if any, its schedule.

    Args:
        optimizer: ``model.optimizer`` (called with ``params``).
        scheduler: ``model.scheduler`` (called with the optimizer and the run
            quantities its signature names, see the module docs), or ``None``.
        params: Parameters or parameter groups (a group without ``lr`` or
            ``weight_decay`` takes the optimizer's).
        trainer: The Lightning trainer (``None`` outside a run: one step per epoch).
        interval: When the schedule steps, ``"step"`` or ``"epoch"``.
        prefer: Keyword arguments the aligner prefers for the optimizer when its
            target takes them and the config does not set them: computation
            only, e.g. ``{"fused": True}`` (the same values, faster).

    Returns:
        The optimizer alone, or Lightning's ``{"optimizer", "lr_scheduler"}`` dict.
    """
    make_opt = resolve(optimizer, "model.optimizer", "params")
    chosen = set(getattr(make_opt, "keywords", {}))
    accepted = _parameters(make_opt)
    extra = {k: v for k, v in (prefer or {}).items() if k in accepted and k not in chosen}
    opt = make_opt(params, **extra)
    if scheduler is None:
        return opt
    make = resolve(scheduler, "model.scheduler", "optimizer")
    wanted = _parameters(make) - set(getattr(make, "keywords", {}))
    run: dict[str, Any] = {}
    if "steps_per_epoch" in wanted:
        from skelagnostic.aligners.schedule import steps_per_epoch

        run["steps_per_epoch"] = steps_per_epoch(trainer)
    if "total_steps" in wanted:
        total = getattr(trainer, "estimated_stepping_batches", 1)
        run["total_steps"] = int(total) if math.isfinite(total) else 1
    if "trainer" in wanted:
        run["trainer"] = trainer
    return {"optimizer": opt, "lr_scheduler": {"scheduler": make(opt, **run), "interval": interval}}


def cyclic_lr(
    optimizer: torch.optim.Optimizer,
    max_lr: float,
    period_epochs: float,
    steps_per_epoch: int = 1,
) -> torch.optim.lr_scheduler.CyclicLR:
    """A triangular cyclic rate (Smith 2017) between the optimizer's ``lr`` and ``max_lr``.

    Args:
        optimizer: Its ``lr`` is the lower bound.
        max_lr: The upper bound.
        period_epochs: The full period (up and down) in epochs.
        steps_per_epoch: Optimizer steps per epoch (given by the run).

    Returns:
        ``torch.optim.lr_scheduler.CyclicLR`` stepped per optimizer step, without
        momentum cycling.
    """
    if not period_epochs > 0:
        raise SkelagnosticError(f"model.scheduler.period_epochs must be > 0, got {period_epochs}")
    lows = [group["lr"] for group in optimizer.param_groups]
    if not all(0 < low <= max_lr for low in lows):
        raise SkelagnosticError(
            f"model.optimizer.lr={lows[0]!r} must be in (0, model.scheduler.max_lr={max_lr!r}]"
        )
    half = max(1, round(period_epochs * steps_per_epoch / 2))
    return torch.optim.lr_scheduler.CyclicLR(
        optimizer,
        base_lr=lows,
        max_lr=max_lr,
        step_size_up=half,
        mode="triangular",
        cycle_momentum=False,
    )


def cosine_lr(
    optimizer: torch.optim.Optimizer, total_steps: int = 1, min_lr: float = 0.0
) -> torch.optim.lr_scheduler.CosineAnnealingLR:
    """The optimizer's ``lr`` decayed by a half cosine to ``min_lr`` over the whole run.

    Args:
        optimizer: Its ``lr`` is the starting rate.
        total_steps: Optimizer steps of the run (given by the run).
        min_lr: The rate at the last step.

    Returns:
        ``torch.optim.lr_scheduler.CosineAnnealingLR`` stepped per optimizer step.
    """
    return torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, T_max=max(1, int(total_steps)), eta_min=min_lr
    )


def linear_warmup(
    optimizer: torch.optim.Optimizer, steps: int
) -> torch.optim.lr_scheduler.LambdaLR:
    """A linear warm-up from ``lr / steps`` to ``lr`` over ``steps`` optimizer steps, then constant.

    Args:
        optimizer: Its ``lr`` is the rate reached.
        steps: Warm-up steps (``0``: constant from the start).

    Returns:
        ``torch.optim.lr_scheduler.LambdaLR`` stepped per optimizer step.
    """
    if steps < 0:
        raise SkelagnosticError(f"model.scheduler.steps must be >= 0, got {steps}")
    warm = max(int(steps), 1)
    return torch.optim.lr_scheduler.LambdaLR(optimizer, functools.partial(_ramp, warm=warm))


def _ramp(step: int, warm: int) -> float:
    """``min(1, (step + 1) / warm)``: a picklable schedule factor (checkpoints hold it)."""
    return min(1.0, (step + 1) / warm)


def _locate(path: str, field: str) -> Callable[..., Any]:
    """The object at dotted ``path`` (``torch.optim.Adam``), imported."""
    module_name, _, attr = path.rpartition(".")
    if not module_name:
        raise SkelagnosticError(f"{field}={path!r} is not a dotted path (e.g. torch.optim.Adam)")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name or "." not in module_name:
            raise SkelagnosticError(f"{field}={path!r}: cannot import it ({exc})") from None
        # a nested attribute (package.Class.method): the owner is an attribute too
        return _attribute(_locate(module_name, field), attr, path, field)
    return _attribute(module, attr, path, field)


def _attribute(owner: Any, attr: str, path: str, field: str) -> Callable[..., Any]:
    """``owner.attr``, callable, or an error naming ``field``."""
    try:
        obj = getattr(owner, attr)
    except AttributeError:
        raise SkelagnosticError(
            f"{field}={path!r}: {getattr(owner, '__name__', owner)!s} has no {attr!r}"
        ) from None
    if not callable(obj):
        raise SkelagnosticError(f"{field}={path!r} is not callable")
    return obj


def _parameters(fn: Callable[..., Any]) -> set[str]:
    """Names ``fn`` accepts (all of them if it takes ``**kwargs``)."""
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):  # a builtin without a signature: pass nothing extra
        return set()
    return set(params)


def _check_arguments(
    target: Callable[..., Any], path: str, kwargs: Mapping[str, Any], field: str
) -> None:
    """Raise when a key of ``kwargs`` is not an argument of ``target`` (or is its first)."""
    try:
        params = inspect.signature(target).parameters
    except (TypeError, ValueError):
        return
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    names = list(params)
    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    accepted = sorted(k for k in names[1:] if params[k].kind in named and k not in RUN_QUANTITIES)
    for key in kwargs:
        if key not in params or key == names[0]:
            raise SkelagnosticError(
                f"{field}.{key} is not an argument of {path}; accepted: {', '.join(accepted)}"
            )
