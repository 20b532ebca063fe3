"""Regenerate the PC-MRL parity fixtures by running the authors' code (issue #26, items 4-5).

Writes, under ``tests/fixtures/pcmrl/``:

* ``authors_knn.pt``: seeded point clouds and what the authors' ``KNNLoss``
  (``models/utils/knn_loss.py``) returns for them (the global, normalised and
  velocity terms) with the gradient of each term with respect to the predicted
  cloud. Their loss needs no pytorch3d.
* ``authors_table1.pt``: a target motion on the CMU skeleton, a network output,
  and the L2P / L2Q / NPSS that the authors' ``eval_inpainter.py``
  (``InpainterEval.eval``) computes from them, with the final prediction and
  target tensors it compares. Their evaluation is run as it is: the data loader
  and the network are replaced by objects that hand out the given motion and
  output, and the results are read from the local variables of ``eval`` when
  it prints its summary line (which rounds to 4 decimals). pyqtgraph and the
  viewer are replaced by no-op stand-ins, ``pytorch3d.transforms``,
  ``pytorch3d.ops`` and ``bezier`` by modules whose functions raise (the skeleton set-up, the loss
  and the evaluation never call them).

Nothing of the authors' code is copied here: it is imported from the checkout
given on the command line (``github.com/MiniEval/PC-MRL``, no licence file).

Usage::

    python -c "import skelagnostic as sa; \
        sa.write_bvh(sa.procedural.generate('biped31', 'walk', seconds=1.0)[0], 'biped31.bvh')"
    python scripts/pcmrl_authors_fixtures.py /path/to/PC-MRL biped31.bvh

The BVH gives the CMU-topology skeleton of the Table 1 fixture (the tests read
it back from the fixture). The committed fixture uses the package's procedural
``biped31`` skeleton (CMU joint names), so it holds nothing of a licensed
dataset; any CMU clip of the cgspeed conversion works too.
"""

from __future__ import annotations

import argparse
import sys
import types
from pathlib import Path
from typing import Any

import torch

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "fixtures" / "pcmrl"

#: Body groups of the authors' clouds.
GROUPS = 5


def _stub_modules() -> None:
    """Stand-ins for the display and pytorch3d modules the authors' files import."""

    def _unavailable(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("pytorch3d is not used by the code paths of the fixtures")

    p3d = types.ModuleType("pytorch3d")
    transforms = types.ModuleType("pytorch3d.transforms")
    transforms.euler_angles_to_matrix = _unavailable  # type: ignore[attr-defined]
    transforms.matrix_to_quaternion = _unavailable  # type: ignore[attr-defined]
    ops = types.ModuleType("pytorch3d.ops")  # models/modules.py's point encoder (unused here)
    ops.knn_points = ops.sample_farthest_points = _unavailable  # type: ignore[attr-defined]
    p3d.transforms = transforms  # type: ignore[attr-defined]
    p3d.ops = ops  # type: ignore[attr-defined]
    sys.modules.setdefault("pytorch3d", p3d)
    sys.modules.setdefault("pytorch3d.transforms", transforms)
    sys.modules.setdefault("pytorch3d.ops", ops)

    bezier = types.ModuleType("bezier")  # models/utils/interp.py's Bezier (unused here)
    bezier.Curve = _unavailable  # type: ignore[attr-defined]
    sys.modules.setdefault("bezier", bezier)

    class _Colour:
        def getRgb(self) -> tuple[int, int, int, int]:
            return (0, 0, 0, 255)

    qtg = types.ModuleType("pyqtgraph")
    qtg.hsvColor = lambda *a, **k: _Colour()  # type: ignore[attr-defined]
    sys.modules.setdefault("pyqtgraph", qtg)

    class _Visualiser:
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            self.width = 1

        def update_data(self, *args: Any, **kwargs: Any) -> None:
            return None

    viewport = types.ModuleType("viewport")
    visualiser = types.ModuleType("viewport.visualiser")
    visualiser.Visualiser = _Visualiser  # type: ignore[attr-defined]
    viewport.visualiser = visualiser  # type: ignore[attr-defined]
    sys.modules.setdefault("viewport", viewport)
    sys.modules.setdefault("viewport.visualiser", visualiser)


# ------------------------------------------------------------------------ KNN loss
def _knn_case(seed: int, batch: int, frames: int, m: int, n: int, dtype: torch.dtype):
    """Seeded source (``expected``) and predicted (``actual``) clouds with one-hot groups."""
    gen = torch.Generator().manual_seed(seed)
    g_e = torch.arange(m) % GROUPS
    g_a = torch.arange(n) % GROUPS
    g_e = g_e[torch.randperm(m, generator=gen)]
    g_a = g_a[torch.randperm(n, generator=gen)]
    # group-dependent body parts moving along a drifting path, plus per-point noise
    drift = torch.cumsum(0.05 * torch.randn(batch, frames, 1, 3, generator=gen), dim=1)
    centre_e = torch.randn(batch, 1, GROUPS, 3, generator=gen)[:, :, g_e]
    centre_a = torch.randn(batch, 1, GROUPS, 3, generator=gen)[:, :, g_a]
    wobble = 0.1 * torch.randn(batch, frames, 1, 3, generator=gen)
    p_e = drift + centre_e + wobble + 0.2 * torch.randn(batch, frames, m, 3, generator=gen)
    p_a = drift + 0.8 * centre_a + 0.3 * torch.randn(batch, frames, n, 3, generator=gen)
    one_e = torch.nn.functional.one_hot(g_e, GROUPS).expand(batch, frames, m, GROUPS)
    one_a = torch.nn.functional.one_hot(g_a, GROUPS).expand(batch, frames, n, GROUPS)
    expected = torch.cat([p_e, one_e.to(p_e.dtype)], dim=-1).to(dtype)
    actual = torch.cat([p_a, one_a.to(p_a.dtype)], dim=-1).to(dtype)
    return expected, actual, g_e, g_a


def knn_fixture() -> dict[str, Any]:
    """Run the authors' ``KNNLoss`` on seeded clouds; inputs, terms and gradients."""
    from models.utils.knn_loss import KNNLoss

    cases = []
    specs = [  # seed, batch, frames, source points, predicted points, k, dtype of the run
        (0, 2, 6, 20, 48, 4, torch.float64),
        (1, 2, 8, 20, 48, 8, torch.float64),
        (2, 2, 8, 16, 30, 3, torch.float64),
    ]
    for seed, batch, frames, m, n, k, dtype in specs:
        # inputs stored in float32 (exact in float64 too); the loss runs in ``dtype``
        expected, actual, g_e, g_a = _knn_case(seed, batch, frames, m, n, torch.float32)
        loss = KNNLoss(GROUPS, k)
        terms, grads = [], []
        for i in range(3):
            x = actual.to(dtype).requires_grad_(True)
            out = loss(expected.to(dtype), x)
            (grad,) = torch.autograd.grad(out[i], x)
            terms.append(out[i].detach())
            grads.append(grad[..., :3].float().contiguous().clone())
        cases.append(
            {
                "k": k,
                "dtype": str(dtype).removeprefix("torch."),
                "expected": expected[..., :3].clone(),
                "actual": actual[..., :3].clone(),
                "expected_groups": g_e,
                "actual_groups": g_a,
                "glob": terms[0],
                "norm": terms[1],
                "vel": terms[2],
                "grad_glob": grads[0],
                "grad_norm": grads[1],
                "grad_vel": grads[2],
            }
        )
    return {"source": "MiniEval/PC-MRL models/utils/knn_loss.py KNNLoss", "cases": cases}


# ------------------------------------------------------------------------ Table 1
class _Loader:
    """Hands out one fixed batch of (root position, local quaternions)."""

    def __init__(self, skeleton: Any, root: torch.Tensor, local_q: torch.Tensor) -> None:
        self.skeleton = skeleton
        self.root, self.local_q = root, local_q

    def load_samples(self, n: int, length: int) -> tuple[torch.Tensor, torch.Tensor]:
        assert n == self.root.shape[0] and length == self.root.shape[1]
        return self.root.clone(), self.local_q.clone()


class _Network(torch.nn.Module):
    """Returns a fixed network output (``[B, T, 3 + 4 V]``) whatever the input."""

    def __init__(self, output: torch.Tensor) -> None:
        super().__init__()
        self.output = output

    def forward(self, x: torch.Tensor, keyframes: torch.Tensor) -> torch.Tensor:
        return self.output.clone()


def _random_unit(gen: torch.Generator, *shape: int) -> torch.Tensor:
    q = torch.randn(*shape, 4, generator=gen)
    return q / q.norm(dim=-1, keepdim=True)


def _smooth_motion(gen: torch.Generator, batch: int, frames: int, joints: int):
    """Smooth random local rotations (sign-continuous) and a walking root, metres."""
    t = torch.linspace(0, 1, frames)[None, :, None, None]
    axis = _random_unit(gen, batch, 1, joints)[..., 1:]
    axis = axis / axis.norm(dim=-1, keepdim=True)
    amp = 0.6 * torch.rand(batch, 1, joints, 1, generator=gen)
    freq = 1 + 3 * torch.rand(batch, 1, joints, 1, generator=gen)
    phase = 6.28 * torch.rand(batch, 1, joints, 1, generator=gen)
    angle = amp * torch.sin(6.28 * freq * t + phase)
    q = torch.cat([torch.cos(angle / 2), torch.sin(angle / 2) * axis], dim=-1)
    base = _random_unit(gen, batch, 1, joints)
    base = torch.where(base[..., :1] < 0, -base, base)
    w1, x1, y1, z1 = base.unbind(-1)
    w2, x2, y2, z2 = q.unbind(-1)
    local = torch.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        dim=-1,
    )
    velocity = torch.randn(batch, 1, 3, generator=gen) * torch.tensor([1.0, 0.0, 1.0])
    root = (
        torch.tensor([0.0, 0.9, 0.0])
        + 4.0 * velocity * t[..., 0]
        + torch.randn(batch, 1, 3, generator=gen)
    )
    return root.float(), local.float()


def table1_fixture(bvh: Path, batch: int = 2, frames: int = 24) -> dict[str, Any]:
    """Run the authors' ``InpainterEval.eval`` on a fixed motion and network output."""
    import eval_inpainter
    from data.cmu import CMUDataLoader

    skeleton = CMUDataLoader.setup_skeleton(str(bvh), "cpu")
    valid = [j for j in range(skeleton.n_joints) if float(skeleton.joint_lengths[j]) > 1e-6]
    gen = torch.Generator().manual_seed(26)
    root, local_q = _smooth_motion(gen, batch, frames, skeleton.n_joints)
    # network output: a root near the truth, global-rotation offsets near identity
    output = torch.cat(
        [
            root
            - root.mean(dim=1, keepdim=True)
            + 0.05 * torch.randn(batch, frames, 3, generator=gen),
            (
                torch.tensor([1.0, 0.0, 0.0, 0.0])
                + 0.3 * torch.randn(batch, frames, len(valid), 4, generator=gen)
            ).flatten(2),
        ],
        dim=-1,
    )

    runs = []
    for gap in (5, 11):
        keys = [*range(0, frames - 1, gap), frames - 1]
        key_idx = torch.tensor(keys, dtype=torch.int64).unsqueeze(0).repeat(batch, 1)
        ev = object.__new__(eval_inpainter.InpainterEval)
        ev.cfg = {"GENERAL": {"max_length": frames}}
        ev.device = "cpu"
        ev.dataloader = _Loader(skeleton, root, local_q)
        ev.tgt_skeleton = skeleton
        ev.valid_joints = torch.tensor(valid, dtype=torch.int64)
        ev.inpainter_model = _Network(output)
        ev.vis = sys.modules["viewport.visualiser"].Visualiser()
        eval_inpainter.device = "cpu"
        eval_inpainter.N_INTERVAL = gap
        seen: dict[str, Any] = {}

        def _capture(*args: Any, _seen: dict[str, Any] = seen) -> None:
            local = sys._getframe(1).f_locals
            for name in (
                "l2p",
                "l2q",
                "npss",
                "p_mean",
                "keyframes",
                "pred_global_p",
                "pred_q_full",
                "real_global_p",
                "real_global_q",
            ):
                value = local[name]
                _seen[name] = value.detach().clone() if torch.is_tensor(value) else list(value)
            print(*args)

        eval_inpainter.print = _capture
        try:
            ev.eval(batch, key_idx, batch_size=batch)
        finally:
            del eval_inpainter.print
        target_rotations = seen["real_global_q"]
        runs.append(
            {
                "gap": gap,
                "keys": seen["keyframes"][0].clone(),
                "centre": seen["p_mean"].reshape(batch, 3),
                # world coordinates: eval compares both after subtracting the keyframe centre
                "pred_positions": seen["pred_global_p"] + seen["p_mean"],
                "pred_rotations": seen["pred_q_full"],
                "target_positions": seen["real_global_p"] + seen["p_mean"],
                "l2p": seen["l2p"][0],
                "l2q": seen["l2q"][0],
                "npss": seen["npss"][0],
            }
        )
    return {
        "source": "MiniEval/PC-MRL eval_inpainter.py InpainterEval.eval",
        "joint_names": list(skeleton.joint_names),
        "parents": list(skeleton.joint_hierarchy),
        "valid_joints": valid,
        # the same target in every run (up to float32 rounding of the centring)
        "target_positions": runs[0]["target_positions"],
        "target_rotations": target_rotations,
        "runs": [{k: v for k, v in run.items() if k != "target_positions"} for run in runs],
    }


def main() -> None:
    """Import the authors' modules from the checkout, run them, write the fixtures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("repo", type=Path, help="checkout of github.com/MiniEval/PC-MRL")
    parser.add_argument("bvh", type=Path, help="a CMU BVH (cgspeed conversion) for the skeleton")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    if not (args.repo / "models" / "utils" / "knn_loss.py").is_file():
        parser.error(
            f"{args.repo} is not a checkout of MiniEval/PC-MRL (no models/utils/knn_loss.py)"
        )
    sys.path.insert(0, str(args.repo.resolve()))
    _stub_modules()
    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.save(knn_fixture(), args.out / "authors_knn.pt")
    torch.save(table1_fixture(args.bvh), args.out / "authors_table1.pt")
    for name in ("authors_knn.pt", "authors_table1.pt"):
        print(f"wrote {args.out / name} ({(args.out / name).stat().st_size} bytes)")


if __name__ == "__main__":
    main()
