"""Training, one module per job: building environments (:mod:`~hrlp.training.environments`), loading runs
(:mod:`~hrlp.training.loading`), logging (:mod:`~hrlp.training.logs`) and the loop (:mod:`~hrlp.training.loop`);
:mod:`hrlp.train` re-exports them, with the settings of :mod:`hrlp.config`."""

from hrlp.training.loading import from_run

__all__ = ["from_run"]
