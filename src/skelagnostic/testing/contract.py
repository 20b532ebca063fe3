"""The aligner contract as a pytest base class: subclass :class:`AlignerContract`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

import pytest

from skelagnostic.testing.checks import (
    ContractRun,
    check_checkpoint_round_trip,
    check_encode_decode,
    check_fit,
    check_length_units,
    check_logging,
    check_steps_without_trainer,
    contract_motion,
    fit_for_contract,
)

if TYPE_CHECKING:
    from skelagnostic.core.motion import Motion
    from skelagnostic.core.skeleton import Skeleton
    from skelagnostic.plugins import PluginManager


class AlignerContract:
    """Base class of a pytest test class that runs the aligner contract (see the module).

    Attributes:
        aligner: The registered ``model=<name>`` to test.
        overrides: Hydra overrides after ``experiment=smoke`` (tiny sizes, data).
        steps: Training steps of the shared run.
    """

    aligner: ClassVar[str] = ""
    overrides: ClassVar[Sequence[str]] = ()
    steps: ClassVar[int] = 4

    def plugin_manager(self) -> PluginManager | None:
        """Where the aligner is registered; ``None`` (the default): the process-wide manager."""
        return None

    def motion(self, run: ContractRun) -> Motion:
        """The clip to encode (default: :func:`contract_motion`)."""
        return contract_motion(run)

    def target_skeleton(self, run: ContractRun, motion: Motion) -> Skeleton:
        """The skeleton to decode onto (default: the clip's own)."""
        return motion.skeleton

    @staticmethod
    @pytest.fixture(scope="class")
    def contract_run(
        request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
    ) -> ContractRun:
        """One short training run shared by the tests of the class.

        A static method on the test class (``request.cls``): pytest deprecates
        class-scoped fixtures defined as instance methods (``PytestRemovedIn10Warning``),
        since the instance they would see is not the tests' one.
        """
        cls: type[AlignerContract] = request.cls
        assert cls.aligner, f"{cls.__name__}: set the class attribute 'aligner'"
        root = tmp_path_factory.mktemp(f"contract-{cls.aligner}")
        return fit_for_contract(
            cls.aligner, root / "run", cls.overrides, cls.steps, cls().plugin_manager()
        )

    def test_fit_a_few_steps(self, contract_run: ContractRun) -> None:
        """Losses logged and finite, weights updated, a checkpoint written."""
        check_fit(contract_run)

    def test_checkpoint_round_trip(self, contract_run: ContractRun) -> None:
        """``load_aligner`` rebuilds the same network from the checkpoint."""
        check_checkpoint_round_trip(contract_run, self.motion(contract_run))

    def test_encode_decode_shapes(self, contract_run: ContractRun) -> None:
        """``encode``/``decode`` (and ``retarget``) shapes, fps and finiteness."""
        motion = self.motion(contract_run)
        check_encode_decode(contract_run, motion, self.target_skeleton(contract_run, motion))

    def test_encode_ignores_the_length_unit(self, contract_run: ContractRun) -> None:
        """A clip in metres, centimetres or an unstated unit encodes the same."""
        check_length_units(contract_run, self.motion(contract_run))

    def test_steps_without_a_trainer(self, contract_run: ContractRun) -> None:
        """Training and validation steps on the data's batches, no Trainer attached."""
        check_steps_without_trainer(contract_run)

    def test_logging_is_ddp_safe(self, contract_run: ContractRun) -> None:
        """``batch_size`` in step logs, ``sync_dist`` for epoch-level values."""
        check_logging(contract_run)
